"""Reconstruction quality against scan sparsity: the runs of a sweep grouped over seeds.

A sweep such as ``python -m nlosfw -m experiment=sparsity`` runs every scene and
acquisition (the *condition*), every sparsity, every field model and every seed. Each
run scores every source it imaged (``true``, ``raw``, ``interp``, ``model`` and the
``compare`` labels) against its full-capture reconstruction. :func:`study_rows`
groups those scores into one :class:`StudyRow` per condition, sparsity and series (a
baseline, or a field model with the options its runs changed) and aggregates over the
seeds: mean, standard deviation (n - 1), minimum and maximum of each score.
:func:`study_figure` plots them against the undersampling factor, one panel row per
condition, one line per series.

With count splitting (``split.count_splitting``, the real-data study ``experiment=sparsity_real``)
every field model also has its held-out measurement error, noise floor and excess
(:data:`FIELD_SCORES`), the reconstructions are scored against half B's full scan, and
``ceiling`` (half A's full scan) is a baseline; ``split.count_splitting_seed`` is then the seed of
every row, and the ``sampling`` group only sets the pattern.

Overrides decide what separates runs: ``model.seed`` (and ``compare.<label>.seed``)
are the seeds; other ``model.*`` overrides are options of the model (a separate
series); ``split.spatial_step``, ``split.pattern``, ``split.spatial_fraction`` and
``split.seed`` set the sparsity (runs of random patterns drawn with different seeds
are aggregated like model seeds); everything else (besides the scene, the
acquisition, the simulator and the noise, which the metrics describe) is part of the
condition.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from nlosfw.common.config import Scalar
from nlosfw.common.text import plain_title
from nlosfw.pipeline.metrics import ImageScores, RunMetrics
from nlosfw.report.quality import unique_legend
from nlosfw.report.records import RunRecord

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.typing import ColorType

#: The reconstruction scores aggregated, in order (attributes of
#: :class:`~nlosfw.pipeline.metrics.ImageScores`).
SCORES = ("psnr", "ssim", "scale_invariant_psnr", "front_view_gain", "volume_psnr",
          "volume_ssim", "depth_rmse_m")

#: Count splitting's field scores (``field.<source>.splits.heldout_measurement``): the
#: held-out measurement error, its noise floor and the excess, in dB.
FIELD_SCORES = ("heldout_excess_db", "heldout_nmse_db", "heldout_floor_db")

#: Sources that are not field models: the reference, the ceiling (count splitting: half
#: A's full scan), the samples imaged directly, interp.
BASELINES = ("true", "ceiling", "raw", "interp")

#: Override keys that the metrics already describe (scene, acquisition) or that run the
#: sweep (experiment, hydra): never part of a condition's label.
#: (``split.thinning`` and ``split.thinning_seed``: count splitting's options in sweeps run
#: before they were renamed.)
_DESCRIBED = re.compile(r"^(scene|acquisition|sampling|simulator|experiment|capture\.path|"
                        r"stop_after|split\.(count_splitting|thinning)(_seed)?|"
                        r"scene\.noise\.model|hydra\..*|figures\..*|cache\..*|output\..*)$")


@dataclass(frozen=True)
class Stat:
    """A score over the runs of a group (None when no run has it)."""

    n: int
    mean: float | None
    std: float | None
    min: float | None
    max: float | None

    @classmethod
    def of(cls, values: Sequence[float | None]) -> Stat:
        xs = [float(v) for v in values if v is not None and math.isfinite(v)]
        if not xs:
            return cls(0, None, None, None, None)
        mean = sum(xs) / len(xs)
        std = (math.sqrt(sum((x - mean) ** 2 for x in xs) / (len(xs) - 1))
               if len(xs) > 1 else 0.0)
        return cls(len(xs), mean, std, min(xs), max(xs))

    def scaled(self, factor: float) -> Stat:
        """The same statistics of the values times ``factor`` (> 0)."""
        def times(v: float | None) -> float | None:
            return None if v is None else factor * v

        return Stat(self.n, times(self.mean), times(self.std), times(self.min), times(self.max))


@dataclass(frozen=True)
class StudyRow:
    """One condition, sparsity and series, aggregated over its runs (seeds)."""

    condition: str
    pattern: str
    undersampling: float
    train_samples: int
    series: str
    kind: str
    """``reference`` (true), ``baseline`` (raw, interp) or ``model``."""
    runs: int
    seeds: tuple[int, ...]
    scores: dict[str, Stat]

    @property
    def sparsity(self) -> str:
        """'16x (256 samples)', with ', random' for random scans."""
        pattern = ", random" if self.pattern == "random" else ""
        return f"{self.undersampling:.3g}x ({self.train_samples} samples{pattern})"

    def to_json(self) -> dict[str, object]:
        return {"condition": self.condition, "pattern": self.pattern,
                "undersampling": self.undersampling, "train_samples": self.train_samples,
                "series": self.series, "kind": self.kind, "runs": self.runs,
                "seeds": list(self.seeds),
                "scores": {name: vars(stat) for name, stat in self.scores.items()}}


def condition_of(record: RunRecord) -> str:
    """What was imaged: 'letter_t, analytic', 'letter_t, embree + poisson', or the capture
    file's name, plus any override that is not a model option, a split or a seed."""
    m = record.metrics
    capture = m.capture
    if capture is not None and capture.source == "file":
        label = Path(capture.path or "capture").name
    else:
        noise = (capture.noise or {}).get("model") if capture is not None else None
        noisy = f" + {noise}" if noise and noise != "none" else ""
        label = f"{m.run.scene}, {m.run.simulator}{noisy}"
    extra = [o for o in record.overrides if _key(o) and not _is_model_or_split(_key(o))
             and not _DESCRIBED.match(_key(o))]
    return " ".join([label, *sorted(extra)])


def series_of(record: RunRecord, source: str) -> tuple[str, str]:
    """(series label, kind) of one source of a run: baselines by name; ``model`` as its
    plugin, compare labels as 'label (plugin)', each with the model options its run
    overrode (seeds aside)."""
    if source == "true":
        return source, "reference"
    if source in BASELINES:
        return source, "baseline"
    entry = record.metrics.field_entry(source)
    plugin = entry.plugin if entry is not None else source
    prefix = "model." if source == "model" else f"compare.{source}."
    options = sorted(o[len(prefix):] for o in record.overrides
                     if o.startswith(prefix) and not _key(o).endswith(".seed"))
    name = plugin if source == "model" else f"{source} ({plugin})"
    return (f"{name} [{' '.join(options)}]" if options else name), "model"


def study_rows(records: Sequence[RunRecord]) -> list[StudyRow]:
    """Every condition x sparsity x series of the completed runs, aggregated over seeds."""
    groups: dict[tuple[str, str, float, int, str, str], list[tuple[RunMetrics, str]]] = {}
    for record in records:
        m = record.metrics
        if m.status != "completed" or m.reconstruction is None or m.split is None:
            continue
        condition = condition_of(record)
        for source in m.reconstruction.sources:
            series, kind = series_of(record, source)
            key = (condition, m.split.pattern, m.split.undersampling, m.split.train_samples,
                   series, kind)
            groups.setdefault(key, []).append((m, source))
    rows = []
    for (condition, pattern, under, samples, series, kind), members in groups.items():
        scores = [m.image_scores(source) for m, source in members]
        split_seeds = [m.capture.count_splitting.seed for m, _ in members
                       if m.capture is not None and m.capture.count_splitting is not None]
        seeds = sorted(set(split_seeds)) if split_seeds else sorted(
            {entry.seed for m, source in members
             if (entry := m.field_entry(source)) is not None
             and entry.seed is not None}) if kind == "model" else []
        stats = {name: Stat.of([_score(s, name) for s in scores]) for name in SCORES}
        stats.update({name: Stat.of([_field_score(m, source, name) for m, source in members])
                      for name in FIELD_SCORES})
        rows.append(StudyRow(
            condition=condition, pattern=pattern, undersampling=under, train_samples=samples,
            series=series, kind=kind, runs=len(members), seeds=tuple(seeds), scores=stats))
    order = {"reference": 0, "baseline": 1, "model": 2}
    rows.sort(key=lambda r: (r.condition, r.pattern, r.undersampling, order[r.kind],
                             BASELINES.index(r.series) if r.kind != "model" else 0, r.series))
    return rows


def _score(scores: ImageScores | None, name: str) -> float | None:
    return None if scores is None else getattr(scores, name)


def _field_score(metrics: RunMetrics, source: str, name: str) -> float | None:
    """A held-out measurement score (``heldout_<key>``) of one source, if it has one."""
    entry = metrics.field_entry(source)
    held = None if entry is None or entry.splits is None else entry.splits.heldout_measurement
    return None if held is None else getattr(held, name.removeprefix("heldout_"))


def _key(override: str) -> str:
    return override.split("=", 1)[0].lstrip("+~") if "=" in override else ""


#: The split options that set a run's sparsity (the figure's x axis and the pattern).
_SPARSITY_KEYS = ("split.spatial_step", "split.pattern", "split.spatial_fraction", "split.seed")


def _is_model_or_split(key: str) -> bool:
    return key == "model" or key.startswith(("model.", "compare.")) or key in _SPARSITY_KEYS


# ---------------------------------------------------------------------- tables
def _cell(stat: Stat, digits: int, scale: float = 1.0) -> str:
    if stat.mean is None:
        return "-"
    mean = f"{stat.mean * scale:.{digits}f}"
    if stat.n > 1 and stat.std is not None:
        return f"{mean} ± {stat.std * scale:.{digits}f}"
    return mean


#: Columns of the study table: (header, score, decimals, scale).
_TABLE = (("PSNR (dB)", "psnr", 1, 1.0), ("SSIM", "ssim", 3, 1.0),
          ("volume PSNR (dB)", "volume_psnr", 1, 1.0), ("volume SSIM", "volume_ssim", 3, 1.0),
          ("depth RMSE (mm)", "depth_rmse_m", 1, 1000.0))


#: Columns of the front view's brightness-matched score, shown when a row has them (runs
#: before they were scored have none): after the SSIM.
_MATCHED_TABLE = (("scale-invariant PSNR (dB)", "scale_invariant_psnr", 1, 1.0),
                  ("front-view gain", "front_view_gain", 2, 1.0))


#: Columns of count splitting's scores, shown when a row has them.
_FIELD_TABLE = (("held-out excess (dB)", "heldout_excess_db", 1, 1.0),
                ("held-out NMSE (dB)", "heldout_nmse_db", 1, 1.0),
                ("noise floor (dB)", "heldout_floor_db", 1, 1.0))


def study_table(rows: Sequence[StudyRow]) -> tuple[list[str], list[list[str]]]:
    """(header, cells) of the study's markdown table: mean ± std over seeds (with count
    splitting, the held-out excess, error and floor first)."""
    def scored(table: tuple[tuple[str, str, int, float], ...]) -> tuple[
            tuple[str, str, int, float], ...]:
        return tuple(c for c in table if any(r.scores[c[1]].n for r in rows))

    columns = scored(_FIELD_TABLE) + _TABLE[:2] + scored(_MATCHED_TABLE) + _TABLE[2:]
    header = ["condition", "sparsity", "source", "runs", "seeds", *[h for h, *_ in columns]]
    cells = [[r.condition, r.sparsity, r.series, str(r.runs),
              ",".join(str(s) for s in r.seeds) or "-",
              *[_reference_cell(r, name) or _cell(r.scores[name], digits, scale)
                for _, name, digits, scale in columns]]
             for r in rows]
    return header, cells


def _reference_cell(row: StudyRow, name: str) -> str:
    """'inf' for the reference's PSNRs (the full capture against itself), else ''."""
    return "inf" if row.kind == "reference" and name.endswith("psnr") else ""


def study_csv_rows(rows: Sequence[StudyRow]) -> tuple[list[str], list[list[Scalar]]]:
    """(header, values) of study.csv: every statistic of every score."""
    header = ["condition", "pattern", "undersampling", "train_samples", "series", "kind", "runs",
              "seeds"]
    for name in (*SCORES, *FIELD_SCORES):
        header += [f"{name}_{stat}" for stat in ("mean", "std", "min", "max")]
    values = []
    for r in rows:
        line: list[Scalar] = [r.condition, r.pattern, f"{r.undersampling:.6g}", r.train_samples,
                           r.series, r.kind, r.runs, " ".join(str(s) for s in r.seeds)]
        for name in (*SCORES, *FIELD_SCORES):
            s = r.scores[name]
            line += ["" if v is None else f"{v:.6g}" for v in (s.mean, s.std, s.min, s.max)]
        values.append(line)
    return header, values


# ---------------------------------------------------------------------- figure
#: Panels of the figure: (score, axis label, scale of the plotted values).
_PANELS = (("heldout_excess_db", "held-out excess error (dB)", 1.0),
           ("psnr", "PSNR of the front view (dB)", 1.0),
           ("ssim", "SSIM of the front view", 1.0),
           ("depth_rmse_m", "depth RMSE (mm)", 1000.0))
_STYLE = {"raw": {"color": "0.45", "linestyle": "--", "marker": "s"},
          "interp": {"color": "black", "linestyle": ":", "marker": "^"},
          "ceiling": {"color": "tab:purple", "linestyle": "-.", "marker": "v"},
          "true": {"color": "tab:green", "linestyle": "-.", "marker": ""}}


def study_figure(rows: Sequence[StudyRow], path: Path, dpi: int = 110) -> None:
    """Quality against undersampling: a row of panels (PSNR, SSIM, depth RMSE) per
    condition, a line per series (mean over seeds, bars from min to max), ``raw`` and
    ``interp`` on every panel (and the full capture's own depth RMSE)."""
    from matplotlib.figure import Figure

    conditions = list(dict.fromkeys(r.condition for r in rows))
    panels = [p for p in _PANELS if any(r.scores[p[0]].n for r in rows)]
    fig = Figure(figsize=(4.6 * len(panels), 3.3 * len(conditions) + 0.8))
    axes = fig.subplots(len(conditions), len(panels), squeeze=False)
    unders = sorted({r.undersampling for r in rows})
    colours: dict[str, ColorType] = {}
    for i, condition in enumerate(conditions):
        mine = [r for r in rows if r.condition == condition]
        for j, (score, label, scale) in enumerate(panels):
            ax = axes[i, j]
            for series in dict.fromkeys((r.series, r.pattern) for r in mine):
                line = sorted((r for r in mine if (r.series, r.pattern) == series),
                              key=lambda r: r.undersampling)
                _plot_series(ax, line, (score, scale), colours)
            ax.set_xscale("log", base=2)
            ax.set_xticks(unders, [f"{u:.3g}x" for u in unders])
            ax.minorticks_off()
            ax.grid(alpha=0.3)
            ax.set_ylabel(label)
            if i == len(conditions) - 1:
                ax.set_xlabel("wall samples of the full capture per sample kept")
            if j == 0:
                ax.set_title(plain_title(condition), loc="left", fontsize=10)
    handles, labels = unique_legend(axes)
    columns = legend_columns(labels, fig.get_figwidth())
    legend_rows = math.ceil(len(labels) / columns) if labels else 0
    fig.legend(handles, labels, loc="upper center", ncol=columns, fontsize=9, frameon=False)
    top = 0.35 + 0.25 * legend_rows  # inches the legend's rows take above the panels
    fig.tight_layout(rect=(0, 0, 1, 1 - top / fig.get_figheight()))
    fig.savefig(path, dpi=dpi, format="png")


#: Inches a legend entry takes per character of its label at font size 9 (generous), and
#: for its marker and the gap to the next entry.
_LEGEND_CHAR_INCHES, _LEGEND_ENTRY_INCHES = 0.075, 0.6


def legend_columns(labels: Sequence[str], width_inches: float, most: int = 6) -> int:
    """How many legend columns fit ``width_inches``: the most (up to ``most``) whose widest
    row, the longest labels side by side, is narrower than the figure."""
    widths = sorted((_LEGEND_ENTRY_INCHES + _LEGEND_CHAR_INCHES * len(label)
                     for label in labels), reverse=True)
    for columns in range(min(most, len(widths)), 1, -1):
        if sum(widths[:columns]) <= 0.95 * width_inches:
            return columns
    return 1


def _plot_series(ax: Axes, line: Sequence[StudyRow], panel: tuple[str, float],
                 colours: dict[str, ColorType]) -> None:
    score, scale = panel
    first = line[0]
    if first.series == "true" and score != "depth_rmse_m":
        return                                           # the reference: inf and 1
    stats = [(r.undersampling, r.scores[score].scaled(scale)) for r in line]
    x = [u for u, s in stats if s.mean is not None]
    mean = [s.mean for _, s in stats if s.mean is not None]
    low = [s.mean - s.min for _, s in stats if s.mean is not None and s.min is not None]
    high = [s.max - s.mean for _, s in stats if s.mean is not None and s.max is not None]
    if not x:
        return
    name = plain_title(first.series) + (" (random)" if first.pattern == "random" else "")
    style = series_style(first.series, first.pattern, first.kind, colours)
    if first.kind != "model":
        if first.series == "true":
            name = "true (full capture)"
        elif first.series == "ceiling":
            name = "ceiling (half A's full scan)"
        ax.plot(x, mean, label=name, linewidth=1.2, markersize=4, color=style.color,
                linestyle=style.linestyle, marker=style.marker, fillstyle=style.fillstyle,
                alpha=style.alpha)
        return
    ax.errorbar(x, mean, yerr=[low, high], markersize=4, capsize=3, linewidth=1.5,
                label=f"{name} (mean, min-max over seeds)", color=style.color,
                linestyle=style.linestyle, marker=style.marker, fillstyle=style.fillstyle,
                alpha=style.alpha)


class SeriesStyle(NamedTuple):
    """How the study figure draws a series."""

    color: ColorType
    linestyle: str
    marker: str
    fillstyle: str = "full"
    alpha: float = 1.0


def series_style(series: str, pattern: str, kind: str,
                 colours: dict[str, ColorType]) -> SeriesStyle:
    """A colour per model (``colours`` assigns them in order) or the reference's own style;
    a random scan pattern draws the same colour dashed, with hollow markers."""
    if kind != "model":
        known = _STYLE[series]
        style = SeriesStyle(known["color"], known["linestyle"], known["marker"])
    else:
        style = SeriesStyle(colours.setdefault(series, f"C{len(colours) % 10}"), "-", "o")
    if pattern == "random":
        style = style._replace(linestyle="--" if style.linestyle == "-" else style.linestyle,
                               fillstyle="none", alpha=0.8)
    return style

"""Quality against the swept parameter: the figure and table of a sweep's report.

A sweep's runs differ in their command-line overrides. :func:`sweep_layout` reads which
keys were swept and lays them out: the key on the x axis (the one asked for, else the
numeric swept key with the most values, else any other, else the model), the model
(``model=...``) as one line per plugin, seeds (``*.seed``) as repeats shown by their mean
and range, and any other swept key as one row of panels per value. Every run contributes
one point per source it imaged: its model (by plugin), each ``compare`` label, ``interp``
and ``raw``, so the baselines are on every panel.

:data:`QUALITY_METRICS` are the panels' columns; a metric no run has is left out. A new
score of :class:`~nlosfw.pipeline.metrics.RunMetrics` is one more :class:`QualityMetric` there
(``image_score("volume_psnr")`` reads a reconstruction score by name).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from nlosfw.common.text import markdown, plain_title
from nlosfw.pipeline.metrics import RunMetrics
from nlosfw.report.records import RunRecord
from nlosfw.report.tables import markdown_table

if TYPE_CHECKING:
    from matplotlib.artist import Artist

#: The sources every run images besides its field models.
BASELINES = ("interp", "raw")


@dataclass(frozen=True)
class QualityMetric:
    """One panel column: a number per (run, source), and which way is better."""

    key: str
    label: str
    better: Literal["lower", "higher"]
    value: Callable[[RunMetrics, str], float | None]
    """The metric of ``source`` in a run's metrics (None where it has none)."""

    @property
    def axis_label(self) -> str:
        return f"{self.label}\n({self.better} is better)"


def image_score(name: str) -> Callable[[RunMetrics, str], float | None]:
    """A source's reconstruction score ``name`` (an :class:`~nlosfw.pipeline.metrics.ImageScores`
    field: ``ssim``, ``psnr``, ...)."""
    def value(metrics: RunMetrics, source: str) -> float | None:
        scores = metrics.image_scores(source)
        return None if scores is None else getattr(scores, name)

    return value


def field_error(split: str, name: str = "nmse_db") -> Callable[[RunMetrics, str], float | None]:
    """A field model's error ``name`` on one set of the protocol (``heldout_pixels``, ...)."""
    def value(metrics: RunMetrics, source: str) -> float | None:
        entry = metrics.field_entry(source)
        if entry is None or entry.splits is None:
            return None
        return getattr(entry.splits.by_set()[split], name)

    return value


def _denoising_gain(metrics: RunMetrics, source: str) -> float | None:
    entry = metrics.field_entry(source)
    return None if entry is None or entry.denoising is None else entry.denoising.gain_db


QUALITY_METRICS: tuple[QualityMetric, ...] = (
    QualityMetric("ssim", "reconstruction SSIM\nagainst the full capture's", "higher",
                  image_score("ssim")),
    QualityMetric("psnr", "reconstruction PSNR (dB)\nagainst the full capture's", "higher",
                  image_score("psnr")),
    QualityMetric("heldout_nmse_db", "field error on held-out\nwall samples, NMSE (dB)", "lower",
                  field_error("heldout_pixels")),
    QualityMetric("denoising_gain_db", "noise removed from\nthe field (dB)", "higher",
                  _denoising_gain),
)


@dataclass(frozen=True)
class SweepLayout:
    """How a sweep's runs are laid out: x axis, lines, repeats and rows of panels."""

    x: str | None
    """The swept override key on the x axis; None: one position per run."""
    facets: tuple[str, ...] = ()
    """Other swept keys: one row of panels per combination of their values."""
    repeats: tuple[str, ...] = ()
    """Swept seeds: their runs are repeats, shown by mean and range."""

    @property
    def x_label(self) -> str:
        return self.x or "run"


def parse_overrides(overrides: Sequence[str]) -> dict[str, str]:
    """``key=value`` overrides by key (``+`` and ``~`` prefixes dropped)."""
    out = {}
    for text in overrides:
        key, sep, value = text.partition("=")
        if sep:
            out[key.lstrip("+~")] = value
    return out


def sweep_layout(records: Sequence[RunRecord], x: str | None = None) -> SweepLayout:
    """The layout of ``records``' quality plot; ``x`` forces the key on the x axis."""
    by_run = [parse_overrides(r.overrides) for r in records]
    keys = list(dict.fromkeys(k for run in by_run for k in run))
    swept = [k for k in keys if len({run.get(k) for run in by_run}) > 1]
    repeats = tuple(k for k in swept if k.split(".")[-1] == "seed")
    candidates = [k for k in swept if k not in repeats and k != "model"]
    if x is None:
        numeric = [k for k in candidates if _numeric([run.get(k) for run in by_run])]
        ranked = sorted(numeric, key=lambda k: -len({run.get(k) for run in by_run}))
        chosen: list[str | None] = [*ranked, *candidates, *(k for k in swept if k == "model")]
        x = (chosen or [None])[0]
    facets = tuple(k for k in candidates if k != x)
    return SweepLayout(x=x, facets=facets, repeats=repeats)


@dataclass(frozen=True)
class QualityPoint:
    """The values of one metric for one line at one x (one per repeated run)."""

    facet: str
    series: str
    x: str
    metric: str
    values: tuple[float, ...]

    @property
    def mean(self) -> float:
        return float(np.mean(self.values))


def quality_points(records: Sequence[RunRecord], layout: SweepLayout,
                   metrics: Sequence[QualityMetric] = QUALITY_METRICS) -> list[QualityPoint]:
    """Every (facet, line, x, metric) of the sweep with the values of its runs."""
    collected: dict[tuple[str, str, str, str], list[float]] = {}
    for record in records:
        overrides = parse_overrides(record.overrides)
        x = record.name if layout.x is None else overrides.get(layout.x, "(default)")
        facet = ", ".join(f"{k}={overrides.get(k, '(default)')}" for k in layout.facets)
        for source, series in _series(record.metrics, layout).items():
            for metric in metrics:
                value = metric.value(record.metrics, source)
                if value is not None and math.isfinite(value):
                    collected.setdefault((facet, series, x, metric.key), []).append(value)
    return [QualityPoint(facet, series, x, metric, tuple(values))
            for (facet, series, x, metric), values in collected.items()]


def _series(metrics: RunMetrics, layout: SweepLayout) -> dict[str, str]:
    """The line each imaged source of a run belongs to, by source."""
    plugins = {source: entry.plugin for source, entry in (metrics.field or {}).items()}
    imaged = [] if metrics.reconstruction is None else list(metrics.reconstruction.sources)
    out = {}
    for source in dict.fromkeys([*plugins, *imaged]):
        if source == "true":
            continue
        if source == "model":
            out[source] = "model" if layout.x == "model" else plugins.get(
                source, metrics.run.model or "model")
        elif source in BASELINES:
            out[source] = source
        else:
            out[source] = f"{source} ({plugins[source]})" if source in plugins else source
    return out


def _numeric(values: Sequence[str | None]) -> bool:
    try:
        return all(v is not None and math.isfinite(float(v)) for v in values)
    except ValueError:
        return False


def _x_order(points: Sequence[QualityPoint]) -> list[str]:
    xs = list(dict.fromkeys(p.x for p in points))
    return sorted(xs, key=float) if _numeric(xs) else xs


def _series_order(points: Sequence[QualityPoint]) -> list[str]:
    series = list(dict.fromkeys(p.series for p in points))
    return [s for s in series if s not in BASELINES] + [b for b in BASELINES if b in series]


_BASELINE_STYLE = {"interp": {"color": "0.15", "linestyle": "--", "marker": "s"},
                   "raw": {"color": "0.55", "linestyle": ":", "marker": "D"}}


def quality_figure(points: Sequence[QualityPoint], layout: SweepLayout,
                   metrics: Sequence[QualityMetric] = QUALITY_METRICS) -> Figure:
    """Quality against the swept parameter: one column per metric, one row per facet, one
    line per model with ``interp`` and ``raw`` on every panel (mean and range of repeats)."""
    shown = [m for m in metrics if any(p.metric == m.key for p in points)]
    facets = list(dict.fromkeys(p.facet for p in points)) or [""]
    xs = _x_order(points)
    numeric = layout.x is not None and _numeric(xs)
    positions = ({x: float(x) for x in xs} if numeric else
                 {x: float(i) for i, x in enumerate(xs)})
    series = _series_order(points)
    colours = {s: f"C{i % 10}" for i, s in enumerate(s for s in series if s not in BASELINES)}
    fig = Figure(figsize=(4.3 * max(len(shown), 1) + 2.2, 3.4 * len(facets) + 1.0),
                 layout="constrained")
    axes = fig.subplots(len(facets), max(len(shown), 1), squeeze=False)
    index = {(p.facet, p.series, p.x, p.metric): p for p in points}
    offsets = {s: (i - (len(series) - 1) / 2) * 0.06 for i, s in enumerate(series)}
    for row, facet in enumerate(facets):
        for col, metric in enumerate(shown):
            ax = axes[row, col]
            for name in series:
                found = [index[k] for x in xs
                         if (k := (facet, name, x, metric.key)) in index]
                if not found:
                    continue
                style = _BASELINE_STYLE.get(name, {"color": colours.get(name, "C0"),
                                                    "linestyle": "-", "marker": "o"})
                if not numeric:
                    style = {**style, "linestyle": "none"}
                px = [positions[p.x] + (0.0 if numeric else offsets[name]) for p in found]
                mean = np.array([p.mean for p in found])
                low = mean - np.array([min(p.values) for p in found])
                high = np.array([max(p.values) for p in found]) - mean
                ax.errorbar(px, mean, yerr=[low, high] if np.any(low + high) else None,
                            label=plain_title(name), capsize=3, markersize=5, **style)
            ax.set_ylabel(metric.axis_label)
            ax.set_xlabel(plain_title(layout.x_label))
            ax.grid(alpha=0.3)
            if facet:
                ax.set_title(plain_title(facet), fontsize=9)
            _x_axis(ax, xs, positions, numeric)
    handles, labels = unique_legend(axes)
    if handles:
        fig.legend(handles, labels, loc="outside right upper", title="field")
    repeat = f"; mean and range over {', '.join(layout.repeats)}" if layout.repeats else ""
    fig.suptitle(f"quality against {plain_title(layout.x_label)} ({_n_runs(points)}{repeat})")
    return fig


def _x_axis(ax: Axes, xs: Sequence[str], positions: Mapping[str, float],
            numeric: bool) -> None:
    values = [positions[x] for x in xs]
    if numeric and min(values) > 0 and max(values) >= 10 * min(values):
        ax.set_xscale("log")
    ax.set_xticks(values, [plain_title(x) for x in xs], rotation=0 if numeric else 30,
                  ha="center" if numeric else "right")
    ax.minorticks_off()


def _n_runs(points: Sequence[QualityPoint]) -> str:
    counts: dict[tuple[str, str], int] = {}
    for p in points:
        key = (p.facet, p.x)
        counts[key] = max(counts.get(key, 0), len(p.values))
    total = sum(counts.values())
    return f"{total} run{'s' if total != 1 else ''}"


@dataclass(frozen=True)
class QualityTable:
    """The numbers of one metric on one row of panels: x down, lines across."""

    heading: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


def quality_tables(points: Sequence[QualityPoint], layout: SweepLayout,
                   metrics: Sequence[QualityMetric] = QUALITY_METRICS) -> list[QualityTable]:
    """The figure's numbers: one table per facet and metric (mean, and range of repeats)."""
    xs = _x_order(points)
    series = _series_order(points)
    index = {(p.facet, p.series, p.x, p.metric): p for p in points}
    tables = []
    for facet in dict.fromkeys(p.facet for p in points):
        for metric in metrics:
            if not any(p.metric == metric.key and p.facet == facet for p in points):
                continue
            where = f" ({facet})" if facet else ""
            rows = tuple((x, *(_cell(index.get((facet, s, x, metric.key))) for s in series))
                         for x in xs)
            tables.append(QualityTable(
                heading=f"{metric.label.replace(chr(10), ' ')}{where}, {metric.better} is "
                        "better", header=(layout.x_label, *series), rows=rows))
    return tables


def quality_table(points: Sequence[QualityPoint], layout: SweepLayout,
                  metrics: Sequence[QualityMetric] = QUALITY_METRICS) -> str:
    """The figure's numbers as markdown (:func:`quality_tables`)."""
    return "\n".join(f"#### {markdown(t.heading)}\n\n" + markdown_table(t.header, t.rows)
                     for t in quality_tables(points, layout, metrics))


def _cell(point: QualityPoint | None) -> str:
    if point is None:
        return ""
    if min(point.values) == max(point.values):
        return f"{point.mean:.4g}"
    return f"{point.mean:.4g} ({min(point.values):.4g} to {max(point.values):.4g})"


def unique_legend(axes: np.ndarray) -> tuple[list[Artist], list[str]]:
    """The legend entries of every panel in ``axes`` (an array of matplotlib axes), each
    label once, in the order first seen: one figure legend for panels sharing lines."""
    handles: list[Artist] = []
    labels: list[str] = []
    for ax in axes.ravel():
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if label not in labels:
                handles.append(handle)
                labels.append(label)
    return handles, labels

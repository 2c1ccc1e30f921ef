"""Sparse scans of measured captures: the real-data study over the shared captures.

    python studies/sparse_scans_measured/run.py run [--captures DIR] [--only NAME ...] [--dir DIR]
                                                    [--reduced] [OVERRIDE ...]
    python studies/sparse_scans_measured/run.py collect DIR [DIR ...] [--reduced] [--out JSON]
                                                    [--add-to [--replace]]
    python studies/sparse_scans_measured/run.py render

``run`` runs ``python -m nlosfw -m experiment=sparsity_real capture.path=FILE`` for every
capture of ``--captures`` (default ``../shared/data/real``; ``--only`` picks some by file
stem) into ``DIR/<stem>`` (count splitting: models train on half A's kept wall points, half
B scores them), then collects them. With no override it runs the whole study (4x, 16x, 64x;
grid and random; rsd_prior, siren_torch, hashgrid_torch, rsd_residual_torch,
neural_volume_torch; three count-splitting seeds; interp in every run). ``--reduced`` runs
the smallest useful part (``model=rsd_prior split.spatial_step=4 sampling=grid
split.count_splitting_seed=0``: interp and rsd_prior at 16x, one seed) and labels the
results as reduced; overrides narrow or extend either. ``collect`` reads every run's
metrics.json (``nlosfw.report``) into ``results.json`` (``--out JSON``: elsewhere, the page
untouched; ``--add-to``: added to the committed results, whose numbers stay, e.g. a new model's
runs; with ``--replace``: in place of an earlier addition of the same models, e.g. a changed
default's runs) and prints the page's generated section; ``render`` rewrites that section and
``figure.png`` from ``results.json``. The scores are the runs' own
(:mod:`nlosfw.evaluation`):

- held-out excess: the error at the wall points not kept against half B's measured field,
  minus the noise floor (the error of a perfect predictor), dB of B's power: lower wins;
- PSNR / SSIM of the reconstruction against half B's full scan; ``ceiling`` is half A's
  full scan scored the same way.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: the shared helpers
import pages
from sweeps import (
    add_runs,
    collect_study,
    fmt,
    paired_rows_of,
    shared_score_differences,
    study_rows_of,
    withdraw_addition,
)

from nlosfw.common import markdown, override_value
from nlosfw.report import StudyRow, markdown_table, study_figure

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CAPTURES = ROOT.parent / "shared" / "data" / "real"
QUESTION = ("On measured captures, at 4×, 16× and 64× fewer wall points, which field model "
            "predicts the unseen wall points best (count splitting), and does it image the "
            "scene better than `interp`?")
FIGURE = "figure.png"
REDUCED = ("model=rsd_prior", "split.spatial_step=4", "sampling=grid",
           "split.count_splitting_seed=0")
#: The study's targets: the best model against interp, averaged over count-splitting seeds.
#: The default model must be the best of ``COMPARED`` or behind it by at most
#: ``default_behind_best_db`` of excess.
TARGETS = {"excess_db": 3.0, "psnr_db": 1.0, "ssim": 0.02, "network_over_rsd_db": 0.5,
           "default_behind_best_db": 0.5}
NETWORK_PLUGINS = ("siren_torch", "hashgrid_torch", "rsd_residual_torch", "neural_volume_torch")
#: The study's default model (``conf/experiment/sparsity_real.yaml``) and the models it must
#: match: the best of them by held-out excess.
DEFAULT_MODEL = "ensemble_torch"
COMPARED = ("rsd_prior", "rsd_residual_torch", "neural_volume_torch")


def main(argv: Sequence[str] | None = None) -> int:
    return pages.main(pages.Study(HERE, run, collect, render, _arguments,
                                  description=__doc__.split("\n\n")[0]), argv)


def _arguments(run_parser: argparse.ArgumentParser,
               collect_parser: argparse.ArgumentParser) -> None:
    run_parser.add_argument("--captures", type=Path, default=CAPTURES,
                            help="folder of .mat captures")
    run_parser.add_argument("--only", nargs="*", default=None, help="capture file stems to run")
    run_parser.add_argument("--dir", type=Path, default=None,
                            help="sweeps go to DIR/<stem> (default: multirun/sparsity-real-<date>)")
    run_parser.add_argument("overrides", nargs="*", help="Hydra overrides for every sweep")
    collect_parser.add_argument("dirs", type=Path, nargs="+")
    collect_parser.add_argument("--add-to", action="store_true",
                                help="add the runs to the committed results.json: rows of the "
                                     "sources it lacks, and the scores its rows lack; every "
                                     "number it has stays")
    collect_parser.add_argument("--replace", action="store_true",
                                help="with --add-to: the runs replace an earlier addition "
                                     "of the same models (e.g. a changed default model's)")
    for parser in (run_parser, collect_parser):
        parser.add_argument("--reduced", action="store_true",
                            help="the reduced study (run: its overrides; both: the label)")
        parser.add_argument("--out", type=Path, default=None,
                            help="write the results here instead of results.json")
        parser.add_argument("--ran-on", default=None,
                            help="where the runs ran, for the text (default: this machine's "
                                 "CPU cores; say so when sweeps ran elsewhere, e.g. a GPU)")


def run(args: argparse.Namespace) -> None:
    """Run one sweep per capture (then ``collect`` reads them)."""
    root = args.dir or ROOT / "multirun" / f"sparsity-real-{time.strftime('%Y%m%d-%H%M%S')}"
    files = sorted(args.captures.glob("*.mat"))
    if args.only:
        files = [f for f in files if f.stem in args.only]
    if not files:
        raise SystemExit(f"{args.captures}: no capture to run (.mat files)")
    args.dirs = []
    for capture in files:
        sweep = (root / capture.stem).resolve()
        extra = [*(REDUCED if args.reduced else ()), *args.overrides]
        command = sweep_command(sweep, capture, extra)
        print("$ " + shlex.join(command), flush=True)
        subprocess.run(command, check=True, cwd=ROOT)
        args.dirs.append(sweep)


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """The study's results from the sweeps' runs; prints the page's generated section."""
    if getattr(args, "replace", False) and not getattr(args, "add_to", False):
        raise SystemExit("collect: --replace replaces an addition to the committed results; "
                         "give --add-to too")
    results: dict[str, Any] = {
        "question": QUESTION, "source": "the runs' metrics.json, read by `run.py collect`",
        "recorded": pages.recorded(args.ran_on or ""), **collect_study(args.dirs)}
    results["reduced"] = bool(args.reduced)
    results["ran_on"] = args.ran_on or f"{results['machine']['cpus']} CPU cores"
    if getattr(args, "add_to", False):
        base = pages.read_results(HERE)
        if getattr(args, "replace", False):
            base = withdraw_addition(base, sorted({r["series"] for r in results["rows"]
                                                   if r["kind"] == "model"}))
        for score, difference in sorted(shared_score_differences(base, results).items()):
            print(f"{score}: the added runs' means differ from the committed by at most "
                  f"{difference:.3g} where both have it")
        results = add_runs(base, results)
    print(results_markdown(results))
    return results


def render(results: dict[str, Any], folder: Path) -> None:
    """The page's generated section and its figure, from ``results``."""
    pages.replace_generated(folder / "README.md", results_markdown(results))
    study_figure(study_rows_of(results), folder / FIGURE, dpi=80)


def sweep_command(sweep: Path, capture: Path, overrides: Sequence[str]) -> list[str]:
    """``python -m nlosfw -m experiment=sparsity_real capture.path=FILE ...``."""
    return [sys.executable, "-m", "nlosfw", "-m", "experiment=sparsity_real",
            f"capture.path={override_value(str(capture.resolve()))}",
            f"hydra.sweep.dir={override_value(str(sweep))}", *overrides]


# ---------------------------------------------------------------------- markdown
def _sparsity(row: StudyRow) -> str:
    return _sparsity_label(row.undersampling, row.pattern)


def _sparsity_label(undersampling: float, pattern: str) -> str:
    """``16×`` (grid) or ``16× random``."""
    return f"{undersampling:.3g}×{' random' if pattern == 'random' else ''}"


def _cells(rows: Sequence[StudyRow]) -> list[tuple[tuple[str, str, float], dict[str, StudyRow]]]:
    """Each capture, pattern and sparsity in the rows' order, with its rows by series."""
    cells: dict[tuple[str, str, float], dict[str, StudyRow]] = {}
    for r in rows:
        cells.setdefault((r.condition, r.pattern, r.undersampling), {})[r.series] = r
    return list(cells.items())


def _gain(row: StudyRow, other: StudyRow | None, score: str,
          lower: bool = False) -> float | None:
    """How much better ``row``'s mean ``score`` is than ``other``'s (``lower``: lower is
    better); None where either lacks it."""
    a = row.scores[score].mean
    b = None if other is None else other.scores[score].mean
    return None if a is None or b is None else (b - a if lower else a - b)


def quality_table(rows: Sequence[StudyRow]) -> str:
    """Every capture, sparsity and source: held-out excess, error and floor (dB), PSNR and
    SSIM against half B's full scan."""
    header = ["capture", "sparsity", "source", "seeds", "held-out excess (dB)",
              "held-out NMSE (dB)", "noise floor (dB)", "PSNR (dB)", "SSIM",
              "scale-invariant PSNR (dB)", "front-view gain", "volume PSNR (dB)",
              "volume SSIM"]
    lines = []
    for r in rows:
        if r.kind == "reference":
            continue
        s = r.scores
        lines.append([r.condition, _sparsity(r), r.series,
                      " ".join(str(x) for x in r.seeds) or "-",
                      fmt(s["heldout_excess_db"], 1), fmt(s["heldout_nmse_db"], 1),
                      fmt(s["heldout_floor_db"], 1), fmt(s["psnr"], 1), fmt(s["ssim"], 3),
                      fmt(s["scale_invariant_psnr"], 1), fmt(s["front_view_gain"], 2),
                      fmt(s["volume_psnr"], 1), fmt(s["volume_ssim"], 3)])
    return markdown_table(header, lines)


def verdicts(rows: Sequence[StudyRow]) -> list[dict[str, Any]]:
    """Per capture and sparsity: the best model (lowest mean excess) against interp, and the
    best network against rsd_prior (excess; positive gains mean better)."""
    out = []
    for cell, by in _cells(rows):
        interp = by.get("interp")
        models = [r for r in by.values() if r.kind == "model"
                  and r.scores["heldout_excess_db"].mean is not None]
        if interp is None or not models:
            continue
        best = min(models, key=lambda r: r.scores["heldout_excess_db"].mean or 1e9)
        nets = [r for r in models if r.series.split(" ")[0] in NETWORK_PLUGINS]
        net = min(nets, key=lambda r: r.scores["heldout_excess_db"].mean or 1e9) if nets else None
        out.append({"capture": cell[0], "pattern": cell[1], "undersampling": cell[2],
                     "model": best.series,
                     "excess_gain_db": _gain(best, interp, "heldout_excess_db", lower=True),
                     "psnr_gain_db": _gain(best, interp, "psnr"),
                     "ssim_gain": _gain(best, interp, "ssim"),
                     "network": None if net is None else net.series,
                     "network_over_rsd_db": None if net is None else _gain(
                         net, by.get("rsd_prior"), "heldout_excess_db", lower=True)})
    return out


def _signed(value: float | None, fmt: str) -> str:
    return "-" if value is None else f"{value:+{fmt}}"


def verdict_table(found: Sequence[dict[str, Any]]) -> str:
    header = ["capture", "sparsity", "best model (excess)", "excess gain vs interp (dB, "
              f"target ≥ {TARGETS['excess_db']:g})", f"PSNR gain (dB, ≥ {TARGETS['psnr_db']:g})",
              f"SSIM gain (≥ {TARGETS['ssim']:g})", "best network",
              f"network vs rsd_prior (dB, ≥ {TARGETS['network_over_rsd_db']:g})"]
    lines = [[v["capture"], _sparsity_label(v["undersampling"], v["pattern"]), v["model"],
              _signed(v["excess_gain_db"], ".1f"), _signed(v["psnr_gain_db"], ".1f"),
              _signed(v["ssim_gain"], ".3f"), v["network"] or "-",
              _signed(v["network_over_rsd_db"], ".1f")] for v in found]
    return markdown_table(header, lines)


def default_verdicts(rows: Sequence[StudyRow],
                     paired: Mapping[tuple[str, str, float, str], StudyRow] | None = None
                     ) -> list[dict[str, Any]]:
    """Per capture and sparsity where the default model ran: its held-out excess behind the
    best of ``COMPARED`` (dB; ≤ 0 when it is the best), and its gains against ``interp``
    (excess, PSNR, SSIM, scale-invariant PSNR, volume PSNR; positive means better), against
    ``interp`` of the default's own runs where ``paired`` has it (runs added later)."""
    out = []
    for cell, by in _cells(rows):
        default = by.get(DEFAULT_MODEL)
        interp = (paired or {}).get((*cell[:2], float(cell[2]), "interp"), by.get("interp"))
        if default is None or interp is None:
            continue
        others = {name: by[name].scores["heldout_excess_db"].mean for name in COMPARED
                  if name in by and by[name].scores["heldout_excess_db"].mean is not None}
        best = min(others, key=lambda name: others[name]) if others else None
        mine = default.scores["heldout_excess_db"].mean
        out.append({"capture": cell[0], "pattern": cell[1], "undersampling": cell[2],
                     "best_compared": best,
                     "behind_best_db": None if best is None or mine is None
                     else mine - others[best],
                     "excess_gain_db": _gain(default, interp, "heldout_excess_db", lower=True),
                     "psnr_gain_db": _gain(default, interp, "psnr"),
                     "ssim_gain": _gain(default, interp, "ssim"),
                     "si_psnr_gain_db": _gain(default, interp, "scale_invariant_psnr"),
                     "volume_psnr_gain_db": _gain(default, interp, "volume_psnr")})
    return out


def _met(v: dict[str, Any]) -> str:
    checks = [(v["behind_best_db"], TARGETS["default_behind_best_db"], True),
              (v["excess_gain_db"], TARGETS["excess_db"], False),
              (v["psnr_gain_db"], TARGETS["psnr_db"], False),
              (v["ssim_gain"], TARGETS["ssim"], False)]
    if any(value is None for value, _, _ in checks):
        return "-"
    return "yes" if all((value <= target) if at_most else (value >= target)
                        for value, target, at_most in checks) else "no"


def default_table(found: Sequence[dict[str, Any]]) -> str:
    header = ["capture", "sparsity", "best of " + ", ".join(COMPARED),
              f"behind it (dB of excess, ≤ {TARGETS['default_behind_best_db']:g})",
              f"excess gain vs interp (dB, ≥ {TARGETS['excess_db']:g})",
              f"PSNR gain (dB, ≥ {TARGETS['psnr_db']:g})", f"SSIM gain (≥ {TARGETS['ssim']:g})",
              "scale-invariant PSNR gain (dB)", "volume PSNR gain (dB)", "all four targets"]
    lines = [[v["capture"], _sparsity_label(v["undersampling"], v["pattern"]),
              v["best_compared"] or "-",
              _signed(v["behind_best_db"], ".1f"), _signed(v["excess_gain_db"], ".1f"),
              _signed(v["psnr_gain_db"], ".1f"), _signed(v["ssim_gain"], ".3f"),
              _signed(v["si_psnr_gain_db"], ".1f"), _signed(v["volume_psnr_gain_db"], ".1f"),
              _met(v)] for v in found]
    return markdown_table(header, lines)


def results_markdown(results: dict[str, Any]) -> str:
    """The page's generated section, from the collected study."""
    rows = study_rows_of(results)
    axes = "; ".join(f"`{k}`: {markdown(', '.join(v))}" for k, v in results["overrides"].items()
                     if k not in ("capture.path", "hydra.sweep.dir"))
    fits = ", ".join(f"{name} {t['mean']:.0f} s (max {t['max']:.0f} s)"
                     for name, t in results["fit_seconds"].items())
    label = ("**Reduced run** (not the whole study): " if results.get("reduced") else "")
    return "\n".join([
        f"{label}generated by `python studies/sparse_scans_measured/run.py render` from "
        f"`results.json`: {results['completed']} completed runs ({results['runs']} in all) on "
        f"{markdown(results.get('ran_on') or str(results['machine']['cpus']) + ' CPU cores')}. "
        f"{pages.recorded_line(results)} What ran (the sweeps' overrides): "
        f"{axes}. Mean fit time: {fits or '-'}.",
        "",
        quality_table(rows),
        "",
        "The best model (lowest held-out excess) against `interp`, and the best network "
        "against `rsd_prior`, with the study's targets (a negative gain is a loss):",
        "",
        verdict_table(verdicts(rows)),
        "",
        *_default_section(rows, paired_rows_of(results)),
        f"![held-out excess, PSNR and SSIM against undersampling]({FIGURE})",
    ]) + "\n"


def _default_section(rows: Sequence[StudyRow],
                     paired: Mapping[tuple[str, str, float, str], StudyRow]) -> list[str]:
    found = default_verdicts(rows, paired)
    if not found:
        return []
    return [f"The default model, `{DEFAULT_MODEL}`, against the best of "
            f"{', '.join(f'`{m}`' for m in COMPARED)} (held-out excess) and against `interp`, "
            "with the scale-invariant and volume PSNR beside (not targets)"
            + (", `interp` scored in the default's own runs" if paired else "") + ":", "",
            default_table(found), ""]


if __name__ == "__main__":
    raise SystemExit(main())

"""Sparse scans of measured captures (issue 22): the real-data study over the shared captures.

Runs ``python -m nlosfw -m experiment=sparsity_real capture.path=FILE`` on each measured
capture (count splitting: models train on half A's kept wall points, half B scores them),
or collects sweeps that ran, and writes ``benchmarks/results/sparsity_real.json`` and the
markdown of the README's "Sparse scans of measured captures" section (printed; ``--readme``
rewrites it between its markers and writes its figure, ``docs/images/sparsity_real.png``).

    python benchmarks/sparsity_real.py run [--captures DIR] [--only NAME ...] [--dir DIR]
                                           [--reduced] [--readme] [OVERRIDE ...]
    python benchmarks/sparsity_real.py collect DIR [DIR ...] [--readme] [--reduced]

``run`` sweeps every capture of ``--captures`` (default ``../shared/data/real``; ``--only``
picks some by file stem) into ``DIR/<stem>``, then collects them. With no override it runs
the whole study (4x, 16x, 64x; grid and random; rsd_prior, siren_torch, hashgrid_torch,
rsd_residual_torch, neural_volume_torch; three count-splitting seeds; interp in every run).
``--reduced`` runs the smallest useful part (``model=rsd_prior split.spatial_step=4
sampling=grid split.count_splitting_seed=0``: interp and rsd_prior at 16x, one seed) and
labels the README section as reduced; overrides narrow or extend either. The scores
(:mod:`nlosfw.evaluation.heldout`):

- held-out excess: the error at the wall points not kept against half B's measured field,
  minus the noise floor (the error of a perfect predictor), dB of B's power: lower wins;
- PSNR / SSIM of the reconstruction against half B's full scan; ``ceiling`` is half A's
  full scan scored the same way.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sparsity_study import _fmt, _rows, collect_study, write_readme_section

from nlosfw.common.text import markdown, override_value
from nlosfw.report.study import StudyRow, study_figure
from nlosfw.report.tables import markdown_table

ROOT = Path(__file__).resolve().parents[1]
CAPTURES = ROOT.parent / "shared" / "data" / "real"
RESULTS = Path(__file__).parent / "results" / "sparsity_real.json"
FIGURE = ROOT / "docs" / "images" / "sparsity_real.png"
MARKERS = ("<!-- sparsity-real-results -->", "<!-- /sparsity-real-results -->")
REDUCED = ("model=rsd_prior", "split.spatial_step=4", "sampling=grid",
           "split.count_splitting_seed=0")
#: The study's targets: the best model against interp, averaged over count-splitting seeds.
TARGETS = {"excess_db": 3.0, "psnr_db": 1.0, "ssim": 0.02, "network_over_rsd_db": 0.5}
NETWORK_PLUGINS = ("siren_torch", "hashgrid_torch", "rsd_residual_torch", "neural_volume_torch")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run the study on every capture, then collect it")
    run.add_argument("--captures", type=Path, default=CAPTURES, help="folder of .mat captures")
    run.add_argument("--only", nargs="*", default=None, help="capture file stems to run")
    run.add_argument("--dir", type=Path, default=None,
                     help="sweeps go to DIR/<stem> (default: multirun/sparsity-real-<date>)")
    run.add_argument("overrides", nargs="*", help="Hydra overrides for every sweep")
    collect = sub.add_parser("collect", help="collect finished sweeps")
    collect.add_argument("dirs", type=Path, nargs="+")
    for command in (run, collect):
        command.add_argument("--reduced", action="store_true",
                             help="the reduced study (run: its overrides; both: the label)")
        command.add_argument("--readme", action="store_true",
                             help="rewrite the README section and its figure")
        command.add_argument("--out", type=Path, default=RESULTS, help="the JSON written")
        command.add_argument("--ran-on", default=None,
                             help="where the runs ran, for the text (default: this machine's "
                                  "CPU cores; say so when sweeps ran elsewhere, e.g. a GPU)")
    args = parser.parse_args(argv)
    if args.command == "run":
        root = args.dir or ROOT / "multirun" / f"sparsity-real-{time.strftime('%Y%m%d-%H%M%S')}"
        files = sorted(args.captures.glob("*.mat"))
        if args.only:
            files = [f for f in files if f.stem in args.only]
        if not files:
            raise SystemExit(f"{args.captures}: no capture to run (.mat files)")
        dirs = []
        for capture in files:
            sweep = (root / capture.stem).resolve()
            extra = [*(REDUCED if args.reduced else ()), *args.overrides]
            command = sweep_command(sweep, capture, extra)
            print("$ " + shlex.join(command), flush=True)
            subprocess.run(command, check=True, cwd=ROOT)
            dirs.append(sweep)
    else:
        dirs = args.dirs
    results = collect_study(dirs)
    results["benchmark"] = "sparsity_real"
    results["reduced"] = bool(args.reduced)
    results["ran_on"] = args.ran_on or f"{results['machine']['cpus']} CPU cores"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    text = results_markdown(results)
    print(text)
    if args.readme:
        write_readme_section(text, MARKERS)
        FIGURE.parent.mkdir(parents=True, exist_ok=True)
        study_figure(_rows(results), FIGURE, dpi=80)
        print(f"README.md: section rewritten ({MARKERS[0]}), figure {FIGURE}")
    print(f"results written to {args.out}")
    return 0


def sweep_command(sweep: Path, capture: Path, overrides: Sequence[str]) -> list[str]:
    """``python -m nlosfw -m experiment=sparsity_real capture.path=FILE ...``."""
    return [sys.executable, "-m", "nlosfw", "-m", "experiment=sparsity_real",
            f"capture.path={override_value(str(capture.resolve()))}",
            f"hydra.sweep.dir={override_value(str(sweep))}", *overrides]


# ---------------------------------------------------------------------- markdown
def _sparsity(row: StudyRow) -> str:
    return f"{row.undersampling:.3g}×{' random' if row.pattern == 'random' else ''}"


def quality_table(rows: Sequence[StudyRow]) -> str:
    """Every capture, sparsity and source: held-out excess, error and floor (dB), PSNR and
    SSIM against half B's full scan."""
    header = ["capture", "sparsity", "source", "seeds", "held-out excess (dB)",
              "held-out NMSE (dB)", "noise floor (dB)", "PSNR (dB)", "SSIM"]
    lines = []
    for r in rows:
        if r.kind == "reference":
            continue
        s = r.scores
        lines.append([r.condition, _sparsity(r), r.series,
                      " ".join(str(x) for x in r.seeds) or "-",
                      _fmt(s["heldout_excess_db"], 1), _fmt(s["heldout_nmse_db"], 1),
                      _fmt(s["heldout_floor_db"], 1), _fmt(s["psnr"], 1), _fmt(s["ssim"], 3)])
    return markdown_table(header, lines)


def verdicts(rows: Sequence[StudyRow]) -> list[dict[str, Any]]:
    """Per capture and sparsity: the best model (lowest mean excess) against interp, and the
    best network against rsd_prior (excess; positive gains mean better)."""
    out = []
    for cell in dict.fromkeys((r.condition, r.pattern, r.undersampling) for r in rows):
        mine = [r for r in rows if (r.condition, r.pattern, r.undersampling) == cell]
        by = {r.series: r for r in mine}
        interp = by.get("interp")
        models = [r for r in mine if r.kind == "model"
                  and r.scores["heldout_excess_db"].mean is not None]
        if interp is None or not models:
            continue
        best = min(models, key=lambda r: r.scores["heldout_excess_db"].mean or 1e9)

        def gain(row: StudyRow, other: StudyRow | None, score: str,
                 lower: bool = False) -> float | None:
            a = row.scores[score].mean
            b = None if other is None else other.scores[score].mean
            return None if a is None or b is None else (b - a if lower else a - b)

        nets = [r for r in models if r.series.split(" ")[0] in NETWORK_PLUGINS]
        net = min(nets, key=lambda r: r.scores["heldout_excess_db"].mean or 1e9) if nets else None
        out.append({"capture": cell[0], "pattern": cell[1], "undersampling": cell[2],
                     "model": best.series,
                     "excess_gain_db": gain(best, interp, "heldout_excess_db", lower=True),
                     "psnr_gain_db": gain(best, interp, "psnr"),
                     "ssim_gain": gain(best, interp, "ssim"),
                     "network": None if net is None else net.series,
                     "network_over_rsd_db": None if net is None else gain(
                         net, by.get("rsd_prior"), "heldout_excess_db", lower=True)})
    return out


def _signed(value: float | None, fmt: str) -> str:
    return "-" if value is None else f"{value:+{fmt}}"


def verdict_table(found: Sequence[dict[str, Any]]) -> str:
    header = ["capture", "sparsity", "best model (excess)", "excess gain vs interp (dB, "
              f"target ≥ {TARGETS['excess_db']:g})", f"PSNR gain (dB, ≥ {TARGETS['psnr_db']:g})",
              f"SSIM gain (≥ {TARGETS['ssim']:g})", "best network",
              f"network vs rsd_prior (dB, ≥ {TARGETS['network_over_rsd_db']:g})"]
    lines = [[v["capture"], f"{v['undersampling']:.3g}×"
              f"{' random' if v['pattern'] == 'random' else ''}", v["model"],
              _signed(v["excess_gain_db"], ".1f"), _signed(v["psnr_gain_db"], ".1f"),
              _signed(v["ssim_gain"], ".3f"), v["network"] or "-",
              _signed(v["network_over_rsd_db"], ".1f")] for v in found]
    return markdown_table(header, lines)


def results_markdown(results: dict[str, Any]) -> str:
    """The README section (between the markers), from the collected study."""
    rows = _rows(results)
    axes = "; ".join(f"`{k}`: {markdown(', '.join(v))}" for k, v in results["overrides"].items()
                     if k not in ("capture.path", "hydra.sweep.dir"))
    fits = ", ".join(f"{name} {t['mean']:.0f} s (max {t['max']:.0f} s)"
                     for name, t in results["fit_seconds"].items())
    label = ("**Reduced run** (not the whole study): " if results.get("reduced") else "")
    return "\n".join([
        f"{label}generated by `python benchmarks/sparsity_real.py` from "
        f"{results['completed']} completed runs ({results['runs']} in all) on "
        f"{markdown(results.get('ran_on') or str(results['machine']['cpus']) + ' CPU cores')}, "
        f"{results['created'][:10]}; the numbers "
        "are in `benchmarks/results/sparsity_real.json`. What ran (the sweeps' overrides): "
        f"{axes}. Mean fit time: {fits or '-'}.",
        "",
        quality_table(rows),
        "",
        "The best model (lowest held-out excess) against `interp`, and the best network "
        "against `rsd_prior`, with issue 22's targets (a negative gain is a loss):",
        "",
        verdict_table(verdicts(rows)),
        "",
        f"![held-out excess, PSNR and SSIM against undersampling]"
        f"({FIGURE.relative_to(ROOT).as_posix()})",
    ]) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())

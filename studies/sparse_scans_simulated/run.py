"""Sparse scans, simulated: reconstruction quality against scan sparsity, per field model.

    python studies/sparse_scans_simulated/run.py run [--dir DIR] [--capture FILE] [OVERRIDE ...]
    python studies/sparse_scans_simulated/run.py collect DIR [DIR ...] [--out JSON]
    python studies/sparse_scans_simulated/run.py render

``run`` is ``python -m nlosfw -m experiment=sparsity hydra.sweep.dir=DIR OVERRIDE...``
followed by ``collect DIR``: with no override it runs the whole study (every model
the preset lists, at its default options, three seeds each). Overrides narrow or
extend it, e.g. ``model=siren_torch,fourier_torch,rsd_prior`` for other models or
``model.steps=1000`` for shorter fits (recorded with the results). ``--capture FILE``
runs the same study on a capture file: the scene and acquisition axes are dropped.
``collect`` reads every run's metrics.json (``nlosfw.report``) into ``results.json``
(``--out JSON``: elsewhere, the page untouched) and prints the page's generated section;
``render`` rewrites that section and ``figure.png`` from ``results.json``.
``run --tuning GRID`` tunes a network's options instead (:data:`TUNING_GRIDS`): one sweep
per candidate on the tuning scenes (noise-free, 16x, seed 0), each candidate's options a
series of its own.

Every score is the run's own (:func:`nlosfw.evaluation.reconstruction_scores`: a source's
reconstruction against the full capture's); a field model wins where its mean over seeds
beats both ``raw`` (the samples imaged directly) and ``interp``. Defaults are never tuned
on the judged scenes: the tuning scenes are ``thesis_planes`` and ``thesis_concave``.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: the shared helpers
import pages
from sweeps import collect_study, fmt, study_rows_of

from nlosfw.common import override_value
from nlosfw.report import StudyRow, markdown_table, study_figure

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
QUESTION = ("At 4×, 16× and 64× fewer wall samples of a simulated scene, does a field "
            "model's upsampled field image the hidden scene better than the kept samples "
            "(`raw`) or their interpolation (`interp`)?")
FIGURE = "figure.png"
TUNING_SCENES = ("thesis_planes", "thesis_concave")
JUDGED_SCENES = ("letter_t", "thesis_two_planes", "thesis_occluded")
#: The networks' tuning grids (``run --tuning GRID``): per candidate, the sweep's overrides
#: (each candidate runs on both tuning scenes, noise-free, at 16x, seed 0).
TUNING_GRIDS: dict[str, list[list[str]]] = {
    "baselines": [["model=siren_torch"]],
    "fourier": [["model=fourier_torch", f"model.sigma={s}"] for s in (1.0, 2.0, 4.0)],
    "wire": [["model=wire_torch", f"model.omega0={w}", f"model.scale0={s}"]
             for w, s in ((5.0, 2.0), (10.0, 5.0), (20.0, 10.0))],
    "finer": [["model=finer_torch", f"model.omega0_first={w}"] for w in (5.0, 15.0, 30.0)],
    "hashgrid": [["model=hashgrid_torch"], ["model=hashgrid_torch", "model.finest_resolution=8"],
                 ["model=hashgrid_torch", "model.encode_frequency=false"]],
}
#: The axes of a tuning sweep (the preset's other axes narrowed to them).
TUNING_AXES = [f"scene={','.join(TUNING_SCENES)}", "acquisition=clean", "split.spatial_step=4",
               "model.seed=0"]
#: Margins a field model must beat the best baseline by (the study's targets, at 16x).
TARGETS = {"noisy_psnr_db": 2.0, "noisy_ssim": 0.05, "clean_psnr_db": 10.0}


def main(argv: Sequence[str] | None = None) -> int:
    return pages.main(pages.Study(HERE, run, collect, render, _arguments,
                                  description=__doc__.split("\n\n")[0]), argv)


def _arguments(run_parser: argparse.ArgumentParser,
               collect_parser: argparse.ArgumentParser) -> None:
    run_parser.add_argument("--dir", type=Path, default=None,
                            help="sweep directory (default: multirun/sparsity-<date>)")
    run_parser.add_argument("--capture", type=Path, default=None,
                            help="run the study on this capture file (no scene axis)")
    run_parser.add_argument("--tuning", choices=sorted(TUNING_GRIDS), default=None,
                            help="a network's tuning grid on the tuning scenes instead: one "
                                 "sweep per candidate, into DIR/<n>")
    run_parser.add_argument("overrides", nargs="*", help="Hydra overrides for the sweep")
    collect_parser.add_argument("dirs", type=Path, nargs="+")
    for parser in (run_parser, collect_parser):
        parser.add_argument("--out", type=Path, default=None,
                            help="write the results here instead of results.json")


def run(args: argparse.Namespace) -> None:
    """Run the sweep (then ``collect`` reads it)."""
    sweep = args.dir or ROOT / "multirun" / f"sparsity-{time.strftime('%Y%m%d-%H%M%S')}"
    sweeps = [(sweep, list(args.overrides))]
    if args.tuning is not None:
        sweeps = [(sweep / str(n), tuning_overrides(candidate, args.overrides))
                  for n, candidate in enumerate(TUNING_GRIDS[args.tuning])]
    for folder, overrides in sweeps:
        command = sweep_command(folder.resolve(), args.capture, overrides)
        print("$ " + shlex.join(command), flush=True)
        subprocess.run(command, check=True, cwd=ROOT)
    args.dirs = [folder for folder, _ in sweeps]


def tuning_overrides(candidate: Sequence[str], overrides: Sequence[str]) -> list[str]:
    """One tuning candidate's sweep: the tuning axes, the candidate's model and options,
    then the user's ``overrides`` (which win)."""
    return [*TUNING_AXES, *candidate, *overrides]


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """The study's results from the sweeps' runs; prints the page's generated section."""
    results = {"question": QUESTION,
               "source": "the runs' metrics.json, read by `run.py collect`",
               "recorded": pages.recorded(), **collect_study(args.dirs)}
    print(results_markdown(results))
    return results


def render(results: dict[str, Any], folder: Path) -> None:
    """The page's generated section and its figure, from ``results``."""
    pages.replace_generated(folder / "README.md", results_markdown(results))
    study_figure(study_rows_of(results), folder / FIGURE, dpi=80)


def sweep_command(sweep: Path, capture: Path | None, overrides: Sequence[str]) -> list[str]:
    """``python -m nlosfw -m experiment=sparsity ...`` for the study."""
    command = [sys.executable, "-m", "nlosfw", "-m", "experiment=sparsity",
               f"hydra.sweep.dir={override_value(str(sweep))}"]
    if capture is not None:
        command += [f"capture.path={override_value(str(capture.resolve()))}",
                    "~hydra.sweeper.params.scene",
                    "~hydra.sweeper.params.acquisition"]
    return command + list(overrides)


# ---------------------------------------------------------------------- markdown
def _scene(condition: str) -> str:
    return condition.split(",", 1)[0]


def _role(condition: str) -> str:
    scene = _scene(condition)
    return "tuning" if scene in TUNING_SCENES else "judged" if scene in JUDGED_SCENES else "other"


def quality_table(rows: Sequence[StudyRow]) -> str:
    """PSNR / SSIM (front view) and depth RMSE of every source: a row per condition and
    source, a column per sparsity."""
    unders = sorted({(r.pattern, r.undersampling) for r in rows})
    header = ["scene, capture", "role", "source"] + [
        f"{u:.3g}×{' random' if p == 'random' else ''}: PSNR dB / SSIM / depth mm"
        for p, u in unders]
    by_key = {(r.condition, r.series, r.pattern, r.undersampling): r for r in rows}
    lines = []
    for condition in dict.fromkeys(r.condition for r in rows):
        for series in dict.fromkeys(r.series for r in rows if r.condition == condition):
            cells = []
            for pattern, under in unders:
                r = by_key.get((condition, series, pattern, under))
                if r is None:
                    cells.append("")
                    continue
                psnr = "∞" if r.kind == "reference" else fmt(r.scores["psnr"], 1)
                cells.append(f"{psnr} / {fmt(r.scores['ssim'], 3)} / "
                             f"{fmt(r.scores['depth_rmse_m'], 1, 1000.0)}")
            lines.append([condition, _role(condition), series, *cells])
    return markdown_table(header, lines)


def _margin(best: StudyRow, baselines: Sequence[StudyRow], score: str,
            lower_is_better: bool = False) -> dict[str, Any] | None:
    """``best``'s mean ``score`` against the better baseline's (gain > 0: ``best`` is better)."""
    ours = best.scores[score].mean
    theirs: list[tuple[float, str]] = [(mean, b.series) for b in baselines
                                       if (mean := b.scores[score].mean) is not None]
    if ours is None or not theirs:
        return None
    value, name = min(theirs) if lower_is_better else max(theirs)
    gain = (value - ours) if lower_is_better else (ours - value)
    return {"model": ours, "baseline": name, "baseline_value": value, "gain": gain}


def verdicts(rows: Sequence[StudyRow]) -> list[dict[str, Any]]:
    """Per condition and sparsity: the best field model (mean PSNR) against the better
    baseline on each score (raw or interp), with the margins."""
    out = []
    cells = dict.fromkeys((r.condition, r.pattern, r.undersampling) for r in rows)
    for condition, pattern, under in cells:
        mine = [r for r in rows if (r.condition, r.pattern, r.undersampling)
                == (condition, pattern, under)]
        models = [r for r in mine if r.kind == "model" and r.scores["psnr"].mean is not None]
        baselines = [r for r in mine if r.kind == "baseline"]
        if not models or not baselines:
            continue
        best = max(models, key=lambda r: r.scores["psnr"].mean or -1e9)
        true = next((r.scores["depth_rmse_m"].mean for r in mine if r.kind == "reference"),
                    None)
        depth = best.scores["depth_rmse_m"].mean
        out.append({"condition": condition, "role": _role(condition), "pattern": pattern,
                    "undersampling": under, "model": best.series,
                    "depth_over_true": depth / true if depth is not None and true else None,
                    "psnr": _margin(best, baselines, "psnr"),
                    "ssim": _margin(best, baselines, "ssim"),
                    "depth_rmse_m": _margin(best, baselines, "depth_rmse_m",
                                            lower_is_better=True)})
    return out


def _gain(margin: dict[str, Any] | None, fmt: str, scale: float = 1.0) -> str:
    if margin is None:
        return "-"
    return f"{scale * margin['gain']:+{fmt}} vs {margin['baseline']}"


def verdict_table(found: Sequence[dict[str, Any]]) -> str:
    header = ["scene, capture", "role", "sparsity", "best model (PSNR)", "PSNR gain (dB)",
              "SSIM gain", "depth RMSE gain (mm)", "depth RMSE / true's", "verdict"]
    lines = []
    for v in found:
        wins = [v[k]["gain"] > 0 for k in ("psnr", "ssim") if v[k] is not None]
        verdict = ("wins" if wins and all(wins) else "loses" if wins and not any(wins)
                   else "mixed")
        lines.append([v["condition"], v["role"],
                      f"{v['undersampling']:.3g}×{' random' if v['pattern'] == 'random' else ''}",
                      v["model"], _gain(v["psnr"], ".1f"), _gain(v["ssim"], ".3f"),
                      _gain(v["depth_rmse_m"], ".1f", 1000.0),
                      "-" if v["depth_over_true"] is None else f"{v['depth_over_true']:.2f}",
                      verdict])
    return markdown_table(header, lines)


def results_markdown(results: dict[str, Any]) -> str:
    """The page's generated section, from the collected study."""
    rows = study_rows_of(results)
    found = verdicts(rows)
    axes = results["overrides"]
    ran = "; ".join(f"`{k}`: {', '.join(v)}" for k, v in axes.items())
    fits = ", ".join(f"{name} {t['mean']:.0f} s (max {t['max']:.0f} s)"
                     for name, t in results["fit_seconds"].items())
    n_win = sum(1 for v in found if v["psnr"] and v["ssim"]
                and v["psnr"]["gain"] > 0 and v["ssim"]["gain"] > 0)
    n_lose = sum(1 for v in found if v["psnr"] and v["ssim"]
                 and v["psnr"]["gain"] <= 0 and v["ssim"]["gain"] <= 0)
    return "\n".join([
        f"Generated by `python studies/sparse_scans_simulated/run.py render` from "
        f"`results.json`: {results['completed']} completed runs ({results['runs']} in all). "
        f"{pages.recorded_line(results)} What ran (the sweep's overrides): {ran}.",
        "",
        "Every score compares a source's reconstruction with the full capture's (`true`): "
        "PSNR and SSIM of the front view (amplitude, maximum over depth, normalised to its "
        "maximum; scikit-image defaults) and the RMS error of each column's brightest depth "
        "against the scene's true depth map (millimetres). `raw` images the kept samples "
        "directly, `interp` their spline (grid) or Clough-Tocher (random) interpolation; "
        "field models show mean ± standard deviation over seeds. Tuning scenes "
        f"({', '.join(TUNING_SCENES)}) are the only ones defaults may be tuned on; the "
        f"others are judged. Mean fit time: {fits or '-'}.",
        "",
        quality_table(rows),
        "",
        f"Best field model against the better baseline per score (a gain > 0 means the model "
        f"is better): it wins on both PSNR and SSIM in {n_win} of {len(found)} cells and "
        f"loses on both in {n_lose}.",
        "",
        verdict_table(found),
        "",
        f"![PSNR, SSIM and depth RMSE against undersampling]({FIGURE})",
    ]) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())

"""The sparsity study (issue 12): reconstruction quality against scan sparsity, per field model.

Runs the sweep of ``conf/experiment/sparsity.yaml`` (scenes x acquisitions x
sparsities x field models x seeds), or collects one that ran, and writes
``benchmarks/results/sparsity_study.json`` and the markdown of the README's
"Results" section (printed; ``--readme`` rewrites that section in place and writes
its figure, ``docs/images/sparsity_study.png``).

    python benchmarks/sparsity_study.py run [--dir DIR] [--capture FILE] [--readme] [OVERRIDE ...]
    python benchmarks/sparsity_study.py collect DIR [DIR ...] [--readme] [--out JSON]

``run`` is ``python -m nlosfw -m experiment=sparsity hydra.sweep.dir=DIR OVERRIDE...``
followed by ``collect DIR``: with no override it runs the whole study (every model
the preset lists, at its default options, three seeds each). Overrides narrow or
extend it, e.g. ``model=siren_torch,fourier_torch,rsd_prior`` for other models or
``model.steps=1000`` for shorter fits (recorded with the results). ``--capture FILE``
runs the same study on a capture file: the scene and acquisition axes are dropped.

Every score compares a source's reconstruction with the full capture's (see
:func:`nlosfw.evaluation.reconstruction_scores`); a field model wins where its mean
over seeds beats both ``raw`` (the samples imaged directly) and ``interp``.
Defaults are never tuned on the judged scenes: the tuning scenes are
``thesis_planes`` and ``thesis_concave``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nlosfw.common.text import override_value
from nlosfw.report.records import RunRecord, find_runs, read_run
from nlosfw.report.study import Stat, StudyRow, study_figure, study_rows
from nlosfw.report.tables import markdown_table

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results" / "sparsity_study.json"
README = ROOT / "README.md"
#: The study's figure as the README shows it (written with ``--readme``).
FIGURE = ROOT / "docs" / "images" / "sparsity_study.png"
MARKERS = ("<!-- sparsity-results -->", "<!-- /sparsity-results -->")
TUNING_SCENES = ("thesis_planes", "thesis_concave")
JUDGED_SCENES = ("letter_t", "thesis_two_planes", "thesis_occluded")
#: Margins a field model must beat the best baseline by (issue 12's targets, at 16x).
TARGETS = {"noisy_psnr_db": 2.0, "noisy_ssim": 0.05, "clean_psnr_db": 10.0}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run the sweep, then collect it")
    run.add_argument("--dir", type=Path, default=None,
                     help="sweep directory (default: multirun/sparsity-<date>)")
    run.add_argument("--capture", type=Path, default=None,
                     help="run the study on this capture file (no scene axis)")
    run.add_argument("overrides", nargs="*", help="Hydra overrides for the sweep")
    collect = sub.add_parser("collect", help="collect finished sweeps")
    collect.add_argument("dirs", type=Path, nargs="+")
    for command in (run, collect):
        command.add_argument("--readme", action="store_true",
                             help="rewrite the README's Results section and its figure")
        command.add_argument("--out", type=Path, default=RESULTS, help="the JSON written")
    args = parser.parse_args(argv)
    if args.command == "run":
        sweep = args.dir or ROOT / "multirun" / f"sparsity-{time.strftime('%Y%m%d-%H%M%S')}"
        command = sweep_command(sweep.resolve(), args.capture, args.overrides)
        print("$ " + shlex.join(command), flush=True)
        subprocess.run(command, check=True, cwd=ROOT)
        dirs = [sweep]
    else:
        dirs = args.dirs
    out = args.out
    results = collect_study(dirs)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    text = results_markdown(results)
    print(text)
    if args.readme:
        write_readme_section(text)
        FIGURE.parent.mkdir(parents=True, exist_ok=True)
        study_figure(_rows(results), FIGURE, dpi=80)
        print(f"README.md: Results section rewritten ({MARKERS[0]}), figure {FIGURE}")
    print(f"results written to {out}")
    return 0


def sweep_command(sweep: Path, capture: Path | None, overrides: Sequence[str]) -> list[str]:
    """``python -m nlosfw -m experiment=sparsity ...`` for the study."""
    command = [sys.executable, "-m", "nlosfw", "-m", "experiment=sparsity",
               f"hydra.sweep.dir={override_value(str(sweep))}"]
    if capture is not None:
        command += [f"capture.path={override_value(str(capture.resolve()))}",
                    "~hydra.sweeper.params.scene",
                    "~hydra.sweeper.params.acquisition"]
    return command + list(overrides)


# ---------------------------------------------------------------------- collect
def collect_study(dirs: Sequence[Path]) -> dict[str, Any]:
    """The study's rows (aggregated over seeds) and what ran, from the runs under ``dirs``."""
    records: list[RunRecord] = []
    for root in dirs:
        records += [read_run(run, root) for run in find_runs(root)]
    rows = study_rows(records)
    completed = [r for r in records if r.metrics.status == "completed"]
    return {
        "benchmark": "sparsity_study",
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "machine": {"platform": platform.platform(), "python": platform.python_version(),
                    "cpus": os.cpu_count()},
        "sweeps": [str(d) for d in dirs],
        "runs": len(records), "completed": len(completed),
        "overrides": _common_overrides(completed),
        "fit_seconds": _fit_seconds(completed),
        "rows": [row.to_json() for row in rows],
    }


def _common_overrides(records: Sequence[RunRecord]) -> dict[str, list[str]]:
    """Every override key of the runs with the values it took (the sweep's axes)."""
    values: dict[str, set[str]] = {}
    for record in records:
        for override in record.overrides:
            key, _, value = override.partition("=")
            values.setdefault(key, set()).add(value)
    return {key: sorted(v) for key, v in sorted(values.items())}


def _fit_seconds(records: Sequence[RunRecord]) -> dict[str, dict[str, float]]:
    """Fit time of each model plugin: mean and maximum over its runs (seconds)."""
    times: dict[str, list[float]] = {}
    for record in records:
        entry = record.metrics.field_entry("model")
        if entry is not None:
            times.setdefault(entry.plugin, []).append(entry.fit.seconds)
    return {name: {"mean": round(sum(t) / len(t), 2), "max": round(max(t), 2), "runs": len(t)}
            for name, t in sorted(times.items())}


# ---------------------------------------------------------------------- markdown
def _rows(results: dict[str, Any]) -> list[StudyRow]:
    return [StudyRow(condition=r["condition"], pattern=r["pattern"],
                     undersampling=r["undersampling"], train_samples=r["train_samples"],
                     series=r["series"], kind=r["kind"], runs=r["runs"], seeds=tuple(r["seeds"]),
                     scores={k: Stat(**v) for k, v in r["scores"].items()})
            for r in results["rows"]]


def _scene(condition: str) -> str:
    return condition.split(",", 1)[0]


def _role(condition: str) -> str:
    scene = _scene(condition)
    return "tuning" if scene in TUNING_SCENES else "judged" if scene in JUDGED_SCENES else "other"


def _fmt(stat: Stat, digits: int, scale: float = 1.0) -> str:
    if stat.mean is None:
        return "-"
    text = f"{stat.mean * scale:.{digits}f}"
    if stat.n > 1 and stat.std:
        text += f" ± {stat.std * scale:.{digits}f}"
    return text


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
                psnr = "∞" if r.kind == "reference" else _fmt(r.scores["psnr"], 1)
                cells.append(f"{psnr} / {_fmt(r.scores['ssim'], 3)} / "
                             f"{_fmt(r.scores['depth_rmse_m'], 1, 1000.0)}")
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
    """The README's Results section (between the markers), from the collected study."""
    rows = _rows(results)
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
        f"Generated by `python benchmarks/sparsity_study.py` from {results['completed']} "
        f"completed runs ({results['runs']} in all) on {results['machine']['cpus']} CPU "
        f"cores, {results['created'][:10]}; the numbers are in "
        "`benchmarks/results/sparsity_study.json`. What ran (the sweep's overrides): "
        f"{ran}.",
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
        f"![PSNR, SSIM and depth RMSE against undersampling]"
        f"({FIGURE.relative_to(ROOT).as_posix()})",
    ]) + "\n"


def write_readme_section(text: str, markers: tuple[str, str] = MARKERS) -> None:
    """Replace the README's text between ``markers`` (default: the Results markers)."""
    readme = README.read_text(encoding="utf-8")
    start, end = markers
    pattern = re.compile(re.escape(start) + r"\n.*?" + re.escape(end), re.S)
    if not pattern.search(readme):
        raise SystemExit(f"README.md: markers {start} ... {end} not found")
    README.write_text(pattern.sub(lambda _: f"{start}\n{text}{end}", readme), encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())

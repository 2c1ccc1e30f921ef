"""The real-data study's default model against the models it must match, per capture and
sparsity: held-out excess, today's image scores, the scale-invariant front view and the
volume scores, and fit times.

Reads runs of ``experiment=sparsity_real`` that kept their reconstructions
(``output.keep=[reconstructions]``), e.g. grid 16x and 64x, thinning seeds 0, 1, 2 on the
shared captures, one sweep for ``model=ensemble_torch`` and one for the candidates::

    python -m nlosfw -m experiment=sparsity_real capture.path=FILE model=ensemble_torch \\
        split.spatial_step=4,8 sampling=grid split.thinning_seed=0,1,2 \\
        'output.keep=[reconstructions]' model.device=cpu
    python benchmarks/default_model_study.py DIR [DIR ...] [--out JSON]

and writes ``benchmarks/results/default_model_study.json``: every run's scores
(:func:`image_scores_analysis.run_scores`), the means over thinning seeds per capture,
sparsity and source, and the verdicts against the targets:

- the default is the best, or within 0.5 dB of the best, of ``rsd_prior``,
  ``rsd_residual_torch`` and ``neural_volume_torch`` in held-out excess;
- it beats ``interp`` by >= 3 dB of excess and by >= 1 dB PSNR and >= 0.02 SSIM of the
  front view (today's scores: each view divided by its own maximum).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from image_scores_analysis import find_runs, run_scores

RESULTS = Path(__file__).parent / "results" / "default_model_study.json"
DEFAULT = "ensemble_torch"
CANDIDATES = ("rsd_prior", "rsd_residual_torch", "neural_volume_torch")
TARGETS = {"within_best_db": 0.5, "excess_over_interp_db": 3.0, "psnr_db": 1.0, "ssim": 0.02}
SCORES = ("excess_db", "psnr", "ssim", "si_psnr", "si_ssim", "volume_psnr", "volume_ssim",
          "gain")


def collect(dirs: Sequence[Path]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(every run's record: its scores, fit seconds and, for the default, its weights;
    the per-(capture, sparsity, source, seed) scores, each seed's baselines once)."""
    runs, table = [], {}
    for path in find_runs(dirs):
        scored = run_scores(path)
        if scored is None:
            continue
        metrics = json.loads((path / "metrics.json").read_text(encoding="utf-8"))
        fit = metrics["field"]["model"]["fit"]
        fitted = fit.get("fitted") or {}
        scored["fit_seconds"] = fit["seconds"]
        scored["weights"] = {k.removeprefix("weight_"): v for k, v in fitted.items()
                             if k.startswith("weight_")}
        if "residual_scale" in fitted:
            scored["residual_scale"] = fitted["residual_scale"]
        runs.append(scored)
        for source, scores in scored["sources"].items():
            key = (scored["capture"], scored["undersampling"], source, scored["thinning_seed"])
            table[key] = {**scores, "fit_seconds": scored["fit_seconds"]
                          if source == scored["model"] else None}
    per_seed = [{"capture": c, "undersampling": u, "source": s, "seed": seed, **v}
                for (c, u, s, seed), v in sorted(table.items())]
    return runs, per_seed


def cell_means(per_seed: Sequence[dict[str, Any]]) -> dict[tuple[str, float], dict[str, Any]]:
    """Means over seeds per (capture, sparsity): {source: {score: mean, seeds: [...]}}."""
    groups: dict[tuple[str, float], dict[str, list[dict[str, Any]]]] = defaultdict(
        lambda: defaultdict(list))
    for row in per_seed:
        groups[(row["capture"], row["undersampling"])][row["source"]].append(row)
    cells = {}
    for key, sources in groups.items():
        cells[key] = {}
        for source, rows in sources.items():
            entry: dict[str, Any] = {"seeds": sorted(r["seed"] for r in rows)}
            for name in (*SCORES, "fit_seconds"):
                values = [r[name] for r in rows if r.get(name) is not None
                          and math.isfinite(r[name])]
                entry[name] = float(np.mean(values)) if values else None
                if name == "fit_seconds" and values:
                    entry["fit_seconds_max"] = float(np.max(values))
            cells[key][source] = entry
    return cells


def verdicts(per_seed: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each cell's default against the best candidate and interp, with the targets: the
    means over the thinning seeds the default ran (every source on the same seeds)."""
    ran = {(r["capture"], r["undersampling"], r["seed"]) for r in per_seed
           if r["source"] == DEFAULT}
    cells = cell_means([r for r in per_seed
                        if (r["capture"], r["undersampling"], r["seed"]) in ran])
    out = []
    for (capture, under), sources in sorted(cells.items()):
        default, interp = sources.get(DEFAULT), sources.get("interp")
        found = {c: sources[c]["excess_db"] for c in CANDIDATES
                 if c in sources and sources[c]["excess_db"] is not None}
        if default is None or interp is None or not found:
            continue
        best = min(found, key=lambda c: found[c])
        gap = default["excess_db"] - found[best]
        excess_gain = interp["excess_db"] - default["excess_db"]
        psnr_gain = default["psnr"] - interp["psnr"]
        ssim_gain = default["ssim"] - interp["ssim"]
        out.append({
            "capture": capture, "undersampling": under, "seeds": default["seeds"],
            "best_candidate": best, "best_candidate_excess_db": found[best],
            "default_excess_db": default["excess_db"], "gap_to_best_db": gap,
            "excess_gain_db": excess_gain, "psnr_gain_db": psnr_gain, "ssim_gain": ssim_gain,
            "si_psnr_gain_db": default["si_psnr"] - interp["si_psnr"],
            "volume_psnr_gain_db": default["volume_psnr"] - interp["volume_psnr"],
            "volume_ssim_gain": default["volume_ssim"] - interp["volume_ssim"],
            "met": {"within_best": gap <= TARGETS["within_best_db"],
                    "excess": excess_gain >= TARGETS["excess_over_interp_db"],
                    "psnr": psnr_gain >= TARGETS["psnr_db"],
                    "ssim": ssim_gain >= TARGETS["ssim"]}})
    return out


def _f(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def markdown(cells: dict[tuple[str, float], dict[str, Any]],
             found: Sequence[dict[str, Any]]) -> str:
    """The scores table and the verdict table."""
    lines = ["| capture | sparsity | source | seeds | excess dB | PSNR | SSIM | SI-PSNR | "
             "gain | vol. PSNR | vol. SSIM | fit s (max) |", "|" + "---|" * 12]
    order = ("ceiling", "raw", "interp", *CANDIDATES, DEFAULT)
    for (capture, under), sources in sorted(cells.items()):
        for source in sorted(sources, key=lambda s: order.index(s) if s in order else 99):
            e = sources[source]
            fit = "-" if e["fit_seconds"] is None else \
                f"{e['fit_seconds']:.0f} ({e['fit_seconds_max']:.0f})"
            lines.append(
                f"| {capture.removeprefix('data_').removesuffix('.mat')} | {under:.0f}x | "
                f"{source} | {' '.join(map(str, e['seeds']))} | {_f(e['excess_db'])} | "
                f"{_f(e['psnr'])} | {_f(e['ssim'], 3)} | {_f(e['si_psnr'])} | "
                f"{_f(e['gain'], 3)} | {_f(e['volume_psnr'])} | {_f(e['volume_ssim'], 3)} | "
                f"{fit} |")
    lines += ["", "| capture | sparsity | best candidate | default - best (dB, <= 0.5) | "
              "excess gain vs interp (dB, >= 3) | PSNR gain (>= 1) | SSIM gain (>= 0.02) | "
              "SI-PSNR gain | volume PSNR gain | volume SSIM gain |", "|" + "---|" * 10]
    for v in found:
        def mark(ok: bool) -> str:
            return "" if ok else " **missed**"
        lines.append(
            f"| {v['capture'].removeprefix('data_').removesuffix('.mat')} | "
            f"{v['undersampling']:.0f}x | {v['best_candidate']} "
            f"({v['best_candidate_excess_db']:.2f}) | {v['gap_to_best_db']:+.2f}"
            f"{mark(v['met']['within_best'])} | {v['excess_gain_db']:+.2f}"
            f"{mark(v['met']['excess'])} | {v['psnr_gain_db']:+.2f}{mark(v['met']['psnr'])} | "
            f"{v['ssim_gain']:+.3f}{mark(v['met']['ssim'])} | {v['si_psnr_gain_db']:+.2f} | "
            f"{v['volume_psnr_gain_db']:+.2f} | {v['volume_ssim_gain']:+.3f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dirs", type=Path, nargs="+", help="folders holding study runs")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the JSON written")
    parser.add_argument("--ran-on", default="", help="where the runs ran, for the record")
    args = parser.parse_args(argv)
    runs, per_seed = collect(args.dirs)
    if not runs:
        print("no run with reconstructions found (output.keep=[reconstructions])")
        return 2
    cells = cell_means(per_seed)
    found = verdicts(per_seed)
    results = {
        "benchmark": "default_model_study", "created": time.strftime("%Y-%m-%d %H:%M"),
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "ran_on": args.ran_on, "default": DEFAULT, "candidates": list(CANDIDATES),
        "targets": TARGETS, "runs": runs, "per_seed": per_seed,
        "cells": [{"capture": c, "undersampling": u, "sources": s}
                  for (c, u), s in sorted(cells.items())],
        "verdicts": found}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    print(markdown(cells, found))
    print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

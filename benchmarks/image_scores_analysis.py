"""Why a better field can make a worse image: the front view's scores taken apart.

Reads runs of the real-data study that kept their reconstructions
(``output.keep=[reconstructions]``) and scores every source (``raw``, ``interp``, the
model, ``ceiling``) against ``true`` (half B's full scan) in several ways:

- ``psnr``, ``ssim``: today's scores (:func:`nlosfw.image.scores.reconstruction_scores`:
  amplitude front views, the maximum over depth, each divided by its own maximum);
- ``si_psnr``, ``si_ssim``: the same front views after the least-squares gain
  g = <a, b> / <b, b> between the test b and the reference a (both max-normalised) is
  applied to the test: what is left when the overall brightness, set by the brightest
  voxel, is taken out; ``gain`` is g (g > 1: the test's front view is darker, relative to
  its peak, than the reference's);
- ``volume_psnr``, ``volume_ssim``: the whole amplitude volumes, as today;
- ``mse_bright`` / ``mse_dark``: the front view's squared error where B's front view is above
  / below its median (after the per-image normalisation, today's score);
- ``sharpness``: the gradient energy of the gain-matched test front view over that of B's
  (1: as sharp as B, below: blurred; B's own noise counts as detail);
- ``peak_ratio``: the front view's maximum over its 99th percentile (a few hot voxels
  setting the normalisation make it large);
- ``depth_spread``: the mean over bright pixels (B's front view above half its maximum) of
  the amplitude summed over depth divided by its maximum over depth, in planes (axial
  blur: energy spread over more planes leaves less in the maximum).

    python benchmarks/image_scores_analysis.py DIR [DIR ...] [--out JSON]

Each DIR is searched for runs (``metrics.json`` beside ``reconstructions/``); a run's model
is labelled with its ``model.*`` overrides (``rsd_prior[tv_weight=0.3]``). The JSON holds
every run's scores and the means per capture, sparsity and source over the thinning seeds.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nlosfw.image.reconstruction_io import read_reconstruction
from nlosfw.image.scores import amplitude, normalise, psnr, ssim

RESULTS = Path(__file__).parent / "results" / "image_scores_analysis.json"
SOURCES = ("raw", "interp", "model", "ceiling")


def least_squares_gain(reference: np.ndarray, test: np.ndarray) -> float:
    """g minimising ||reference - g test||^2 (1 for a zero test)."""
    denom = float(np.sum(test * test))
    return float(np.sum(reference * test)) / denom if denom > 0 else 1.0


def gradient_energy(image: np.ndarray) -> float:
    """Mean squared finite difference along both axes."""
    return float(np.mean(np.diff(image, axis=0) ** 2) + np.mean(np.diff(image, axis=1) ** 2))


def source_scores(ref_volume: np.ndarray, test_volume: np.ndarray) -> dict[str, float]:
    """Every score of one amplitude volume (Z, Y, X) against the reference's."""
    a, b = normalise(ref_volume.max(axis=0)), normalise(test_volume.max(axis=0))
    g = least_squares_gain(a, b)
    matched = g * b
    bright = a > np.median(a)
    va, vb = normalise(ref_volume), normalise(test_volume)
    lit = a > 0.5
    total, peak = test_volume.sum(axis=0), test_volume.max(axis=0)
    spread = float(np.mean(total[lit] / np.maximum(peak[lit], 1e-30))) if lit.any() else math.nan
    return {
        "psnr": psnr(a, b), "ssim": ssim(a, b),
        "si_psnr": psnr(a, matched), "si_ssim": ssim(a, matched), "gain": g,
        "volume_psnr": psnr(va, vb), "volume_ssim": ssim(va, vb),
        "si_volume_psnr": psnr(va, least_squares_gain(va, vb) * vb),
        "mse_bright": float(np.mean((a[bright] - b[bright]) ** 2)),
        "mse_dark": float(np.mean((a[~bright] - b[~bright]) ** 2)),
        "mean_front": float(np.mean(b)),
        "sharpness": gradient_energy(matched) / gradient_energy(a),
        "peak_ratio": float(b.max() / max(np.percentile(b, 99), 1e-30)),
        "depth_spread": spread,
    }


def run_scores(run: Path) -> dict[str, Any] | None:
    """The scores of every source of the run in ``run`` (None: no reconstructions)."""
    folder = run / "reconstructions"
    if not (folder / "true.hdf5").is_file():
        return None
    metrics = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
    ref = amplitude(read_reconstruction(folder / "true.hdf5").as_volume()[0])
    plugin = metrics["field"]["model"]["plugin"] + model_options(run)
    out: dict[str, Any] = {
        "run": str(run), "capture": Path(metrics["capture"]["path"]).name,
        "undersampling": metrics["split"]["undersampling"],
        "pattern": metrics["split"]["pattern"],
        "thinning_seed": metrics["capture"]["thinning"]["seed"], "model": plugin,
        "ref": {"peak_ratio": float(normalise(ref.max(axis=0)).max()
                                    / np.percentile(normalise(ref.max(axis=0)), 99)),
                "mean_front": float(np.mean(normalise(ref.max(axis=0))))},
        "sources": {}}
    for source in SOURCES:
        path = folder / f"{source}.hdf5"
        if not path.is_file():
            continue
        test = amplitude(read_reconstruction(path).as_volume()[0])
        name = plugin if source == "model" else source
        scores = source_scores(ref, test)
        field = metrics["field"].get(source if source != "model" else "model", {})
        held = (field.get("splits") or {}).get("heldout_measurement") or {}
        scores["excess_db"] = held.get("excess_db")
        recorded = metrics["reconstruction"]["sources"].get(source, {})
        scores["recorded_psnr"] = recorded.get("psnr")
        out["sources"][name] = scores
    return out


def model_options(run: Path) -> str:
    """The run's ``model.<option>`` overrides (but the device) as a label suffix,
    ``[tv_weight=0.3]``; empty without any (``.hydra/overrides.yaml``)."""
    path = run / ".hydra" / "overrides.yaml"
    if not path.is_file():
        return ""
    import yaml

    overrides = yaml.safe_load(path.read_text(encoding="utf-8")) or []
    options = [o.removeprefix("model.") for o in overrides
               if str(o).startswith("model.") and not str(o).startswith("model.device=")]
    return f"[{','.join(options)}]" if options else ""


def find_runs(dirs: Sequence[Path]) -> list[Path]:
    """Every run folder under ``dirs`` with a metrics.json."""
    runs = []
    for d in dirs:
        runs += sorted(p.parent for p in d.rglob("metrics.json"))
    return runs


def summarise(runs: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Means per (capture, pattern, sparsity, source) over runs (interp, raw and ceiling are
    in every run of a cell: their values are averaged over the cell's distinct seeds)."""
    groups: dict[tuple[str, str, float, str], dict[int, dict[str, float]]] = defaultdict(dict)
    for run in runs:
        for source, scores in run["sources"].items():
            key = (run["capture"], run["pattern"], run["undersampling"], source)
            groups[key][run["thinning_seed"]] = scores
    rows = []
    for (capture, pattern, under, source), by_seed in sorted(groups.items()):
        names = next(iter(by_seed.values())).keys()
        means = {}
        for name in names:
            values = [s[name] for s in by_seed.values() if s.get(name) is not None]
            means[name] = float(np.mean(values)) if values else None
        rows.append({"capture": capture, "pattern": pattern, "undersampling": under,
                     "source": source, "seeds": sorted(by_seed), **means})
    return rows


def _f(value: float | None, digits: int = 2) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table."""
    head = ("| capture | sparsity | source | excess dB | PSNR | SI-PSNR | gain | SSIM | SI-SSIM "
            "| vol. PSNR | vol. SSIM | MSE bright | MSE dark | sharpness | depth spread |")
    lines = [head, "|" + "---|" * 15]
    for r in rows:
        lines.append(
            f"| {r['capture'].removeprefix('data_').removesuffix('.mat')} | "
            f"{r['undersampling']:.0f}x {r['pattern']} | {r['source']} | "
            f"{_f(r.get('excess_db'), 1)} | {_f(r['psnr'])} | {_f(r['si_psnr'])} | "
            f"{_f(r['gain'], 3)} | {_f(r['ssim'], 3)} | {_f(r['si_ssim'], 3)} | "
            f"{_f(r['volume_psnr'])} | {_f(r['volume_ssim'], 3)} | {_f(r['mse_bright'], 4)} | "
            f"{_f(r['mse_dark'], 4)} | {_f(r['sharpness'], 2)} | {_f(r['depth_spread'], 1)} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dirs", type=Path, nargs="+", help="folders holding study runs")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the JSON written")
    args = parser.parse_args(argv)
    runs = [r for r in (run_scores(p) for p in find_runs(args.dirs)) if r is not None]
    if not runs:
        print("no run with reconstructions found (output.keep=[reconstructions])",
              file=sys.stderr)
        return 2
    rows = summarise(runs)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"benchmark": "image_scores_analysis", "runs": runs,
                                    "summary": rows}, indent=1) + "\n", encoding="utf-8")
    print(markdown(rows))
    print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

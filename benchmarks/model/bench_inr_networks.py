"""Speed and tuning of the sparse-scan networks (fourier, wire, finer, hashgrid; torch and JAX).

Data: the tuning scenes ``thesis_planes`` and ``thesis_concave`` (64 x 64 wall,
``analytic`` simulator, noise-free), the ``fft`` transform's default 151 frequencies,
split as the study does with ``split.spatial_step=4``: 16 x 16 wall samples and 135
training frequencies (every tenth held out). Never the judged scenes.

``speed``: wall-clock time of ``fit`` with each model's default options on the
``thesis_planes`` split (16 x 16 x 135), the minimum of ``--repeats`` fits (the
machine is shared with other jobs: the minimum is the least disturbed run).
Target: at most 60 s on 2 cores.

``tune``: fits the candidate options of ``--grid`` (see :data:`GRIDS`) on both
tuning scenes and scores each prediction:

* the field's held-out pixels (wall samples the model never saw): NMSE in dB;
* the reconstruction: the full 64 x 64 field the model predicts is imaged with the
  ``fft`` imager on the pipeline's voxels (24 depths spanning the scene, the wall's
  whole width) and compared with the full capture's reconstruction: PSNR and SSIM of
  the front-view maximum projection of amplitudes (square root of intensity), each
  normalised to its maximum, with scikit-image's defaults, and the intensity-MIP
  PSNR/SSIM, all computed by :mod:`nlosfw.evaluation` as a run computes them.

``raw`` (the 16 x 16 samples imaged directly) and ``interp`` are scored alike.
Results go to ``benchmarks/results/bench_inr_networks.json`` (``--update`` keeps the
runs of earlier invocations).

    python benchmarks/model/bench_inr_networks.py speed [--repeats 2] [--models fourier_torch,...]
    python benchmarks/model/bench_inr_networks.py tune --grid fourier [--update]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, machine, write_results

from nlosfw.evaluation import (
    FieldSplit,
    field_metrics,
    image_metrics,
    reconstruction_scores,
    split_field,
)
from nlosfw.image import Reconstruction, volume_voxels
from nlosfw.plugins import load_plugins
from nlosfw.simulate import builtin_scene
from nlosfw.transform import PhasorField

RESULTS = RESULTS_DIR / "bench_inr_networks.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('machine', 'speed', 'split')
#: Keys written only by some modes.
OPTIONAL_KEYS = ('baselines', 'tuning')
TUNING_SCENES = ("thesis_planes", "thesis_concave")
SPATIAL_STEP = 4
MODELS = tuple(f"{n}_{e}" for n in ("fourier", "wire", "finer", "hashgrid", "siren")
               for e in ("torch", "jax"))
TARGET_FIT_S = 60.0

#: Candidate options per grid (each tried on both tuning scenes, torch engine).
GRIDS: dict[str, list[tuple[str, dict[str, Any]]]] = {
    "baselines": [("siren_torch", {})],
    "fourier": [("fourier_torch", {"sigma": s}) for s in (1.0, 2.0, 4.0)],
    "wire": [("wire_torch", {"omega0": w, "scale0": s}) for w, s in
             ((5.0, 2.0), (10.0, 5.0), (20.0, 10.0))],
    "finer": [("finer_torch", {"omega0_first": w}) for w in (5.0, 15.0, 30.0)],
    "hashgrid": [("hashgrid_torch", o) for o in (
        {}, {"finest_resolution": 8}, {"encode_frequency": False})],
}


@dataclass(frozen=True)
class TuningData:
    """One scene's full field, its split, the voxels and the reference reconstruction."""

    scene: str
    field: PhasorField
    split: FieldSplit
    voxels: np.ndarray
    reference: Reconstruction


def scene_depths(capture: Any, n_depths: int = 24) -> np.ndarray:
    """The pipeline's default depths: the ground truth's span with a margin."""
    depth = np.asarray(capture.scene_info["ground_truth"]["depth"], dtype=float)
    hit = depth[depth > 0]
    lo, hi = float(hit.min()), float(hit.max())
    margin = max(0.15, 0.25 * (hi - lo))
    return np.linspace(max(0.05, lo - margin), hi + margin, n_depths)


@cache
def tuning_data(scene: str) -> TuningData:
    """Simulate, transform, split and image the full field of ``scene`` (once)."""
    registry = load_plugins().registry
    capture = registry.create("simulator", "analytic", {}).simulate(builtin_scene(scene))
    field = registry.create("transform", "fft", {}).transform(capture)
    split = split_field(field, spatial_step=SPATIAL_STEP, spectral="interleaved",
                        spectral_fraction=0.1)
    ny, nx = field.grid_shape
    dy, dx = field.grid_spacing()
    x0, y0 = field.wall_xyz[0, 0, 0] - dx / 2, field.wall_xyz[0, 0, 1] - dy / 2
    voxels = volume_voxels(scene_depths(capture), (x0, x0 + nx * dx), (y0, y0 + ny * dy),
                           (ny, nx))
    return TuningData(scene, field, split, voxels, imager().reconstruct(field, voxels))


@cache
def imager() -> Any:
    return load_plugins().registry.create("imager", "fft", {})


def scores(data: TuningData, predicted: PhasorField) -> dict[str, Any]:
    """Reconstruction scores of ``predicted`` (any wall grid) against the full capture's, the
    run's own (:mod:`nlosfw.evaluation`): amplitudes' front view and volume, and the
    intensity MIP's."""
    recon = imager().reconstruct(predicted, data.voxels)
    amplitude = reconstruction_scores(data.reference, recon)
    intensity = image_metrics(data.reference.max_intensity_image(), recon.max_intensity_image())
    return {"mip_psnr": amplitude["psnr"], "mip_ssim": amplitude["ssim"],
            "volume_psnr": amplitude["volume_psnr"], "volume_ssim": amplitude["volume_ssim"],
            "intensity_mip_psnr": intensity["psnr"], "intensity_mip_ssim": intensity["ssim"]}


def baseline_rows(data: TuningData) -> list[dict[str, Any]]:
    """``raw`` (the sparse samples imaged directly) and ``interp``."""
    step = data.split.spatial_step
    raw = data.field.select(y=slice(None, None, step), x=slice(None, None, step))
    rows = [{"scene": data.scene, "model": "raw", "options": {}, **scores(data, raw)}]
    rows.append(run_model(data, "interp", {}))
    return rows


def run_model(data: TuningData, name: str, options: dict[str, Any], seed: int = 0
              ) -> dict[str, Any]:
    """Fit ``name`` with ``options`` on the scene's split; score field and reconstruction."""
    registry = load_plugins().registry
    neural = name != "interp"
    opts = {**options, "device": "cpu", "seed": seed} if neural else dict(options)
    model = registry.create("model", name, opts)
    start = time.perf_counter()
    report = model.fit(data.split.train_field)
    fit_s = time.perf_counter() - start
    full = data.field
    predicted = model.predict_field(full.wall_xyz, full.frequencies, full.geometry, full.weights)
    errors = field_metrics(full, predicted, data.split)["heldout_pixels"]
    row = {"scene": data.scene, "model": name, "options": options, "seed": seed,
           "fit_s": fit_s, "steps": report.steps, "n_parameters": int(model.n_parameters),
           "heldout_pixels_nmse_db": errors["nmse_db"],
           "heldout_pixels_relative_l2": errors["relative_l2"], **scores(data, predicted)}
    print(f"{data.scene:15s} {name:15s} {json.dumps(options):60s} fit {fit_s:5.1f} s  "
          f"NMSE {row['heldout_pixels_nmse_db']:6.2f} dB  MIP PSNR {row['mip_psnr']:5.2f} "
          f"SSIM {row['mip_ssim']:.3f}  vol PSNR {row['volume_psnr']:5.2f}", flush=True)
    return row


def speed(models: list[str], repeats: int) -> list[dict[str, Any]]:
    """Minimum over ``repeats`` of the default fit's wall-clock time, per model."""
    data = tuning_data("thesis_planes")
    registry = load_plugins().registry
    rows = []
    for name in models:
        times, steps = [], 0
        for _ in range(repeats):
            model = registry.create("model", name, {"device": "cpu"})
            start = time.perf_counter()
            steps = model.fit(data.split.train_field).steps
            times.append(time.perf_counter() - start)
        rows.append({"model": name, "fit_s_min": min(times), "fit_s_all": times,
                     "steps": steps, "ms_per_step": 1000 * min(times) / steps,
                     "n_parameters": int(model.n_parameters),
                     "meets_target": min(times) <= TARGET_FIT_S,
                     "load_average": os.getloadavg()[0]})
        print(f"{name:15s} fit {min(times):6.1f} s (min of {times}), {steps} steps, "
              f"{rows[-1]['n_parameters']} parameters", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mode", choices=("speed", "tune"))
    parser.add_argument("--models", default=",".join(MODELS))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--grid", default="baselines", help=", ".join(GRIDS))
    parser.add_argument("--options", default=None,
                        help="tune: one JSON object of options (with --model) instead of a grid")
    parser.add_argument("--model", default=None)
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--label", default=None, help="tune: a label stored with the rows")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--update", action="store_true",
                        help="keep the results of earlier invocations in --out")
    args = parser.parse_args()
    results: dict[str, Any] = {}
    if args.update and args.out.is_file():
        results = json.loads(args.out.read_text())
    results["machine"] = machine(note="2 shared cores; timings are minima of repeats")
    results["split"] = {"spatial_step": SPATIAL_STEP, "spectral": "interleaved",
                        "spectral_fraction": 0.1, "scenes": list(TUNING_SCENES)}
    if args.mode == "speed":
        models = [m for m in args.models.split(",") if m]
        old = {r["model"]: r for r in results.get("speed", [])}
        old.update({r["model"]: r for r in speed(models, args.repeats)})
        results["speed"] = list(old.values())
    else:
        runs = results.setdefault("tuning", [])
        if "baselines" not in results:
            results["baselines"] = [r for s in TUNING_SCENES for r in baseline_rows(tuning_data(s))]
        candidates = ([(args.model, json.loads(args.options))] if args.options
                      else GRIDS[args.grid])
        for name, options in candidates:
            for seed in (int(s) for s in args.seeds.split(",")):
                for scene in TUNING_SCENES:
                    row = run_model(tuning_data(scene), name, options, seed)
                    row["label"] = args.label or args.grid
                    runs.append(row)
                    write(args.out, results)            # after every fit: runs are long
    write(args.out, results)


def write(path: Path, results: dict[str, Any]) -> None:
    write_results(path, results, RESULT_KEYS, OPTIONAL_KEYS, indent=1)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

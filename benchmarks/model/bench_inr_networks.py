"""Speed of the sparse-scan networks (fourier, wire, finer, hashgrid, siren; torch and JAX).

Data: the tuning scene ``thesis_planes`` (64 x 64 wall, ``analytic`` simulator,
noise-free), the ``fft`` transform's default 151 frequencies, split as the study does
with ``split.spatial_step=4``: 16 x 16 wall samples and 135 training frequencies (every
tenth held out).

Wall-clock time of ``fit`` with each model's default options on that split, the minimum
of ``--repeats`` fits (the machine is shared with other jobs: the minimum is the least
disturbed run). Target: at most 60 s on 2 cores. Results go to
``benchmarks/results/bench_inr_networks.json`` (``--update`` keeps the rows of models not
re-run).

How well the networks' options do (their tuning on ``thesis_planes`` and
``thesis_concave``) is a study: ``studies/sparse_scans_simulated`` (``run.py run
--tuning GRID``).

    python benchmarks/model/bench_inr_networks.py [--repeats 2] [--models M,...] [--update]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from functools import cache
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, machine, write_results

from nlosfw.evaluation import FieldSplit, split_field
from nlosfw.plugins import load_plugins
from nlosfw.simulate import builtin_scene

RESULTS = RESULTS_DIR / "bench_inr_networks.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('machine', 'speed', 'split')
SCENE = "thesis_planes"
SPATIAL_STEP = 4
MODELS = tuple(f"{n}_{e}" for n in ("fourier", "wire", "finer", "hashgrid", "siren")
               for e in ("torch", "jax"))
TARGET_FIT_S = 60.0


@cache
def scene_split(scene: str) -> FieldSplit:
    """Simulate, transform and split ``scene`` (once)."""
    registry = load_plugins().registry
    capture = registry.create("simulator", "analytic", {}).simulate(builtin_scene(scene))
    field = registry.create("transform", "fft", {}).transform(capture)
    return split_field(field, spatial_step=SPATIAL_STEP, spectral="interleaved",
                       spectral_fraction=0.1)


def speed(models: list[str], repeats: int) -> list[dict[str, Any]]:
    """Minimum over ``repeats`` of the default fit's wall-clock time, per model."""
    split = scene_split(SCENE)
    registry = load_plugins().registry
    rows = []
    for name in models:
        times, steps = [], 0
        for _ in range(repeats):
            model = registry.create("model", name, {"device": "cpu"})
            start = time.perf_counter()
            steps = model.fit(split.train_field).steps
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
    parser.add_argument("--models", default=",".join(MODELS))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--update", action="store_true",
                        help="keep the rows of models not re-run from --out")
    args = parser.parse_args()
    results: dict[str, Any] = {}
    if args.update and args.out.is_file():
        results = json.loads(args.out.read_text())
    results["machine"] = machine(note="2 shared cores; timings are minima of repeats")
    results["split"] = {"spatial_step": SPATIAL_STEP, "spectral": "interleaved",
                        "spectral_fraction": 0.1, "scenes": [SCENE]}
    models = [m for m in args.models.split(",") if m]
    old = {r["model"]: r for r in results.get("speed", [])}
    old.update({r["model"]: r for r in speed(models, args.repeats)})
    results["speed"] = list(old.values())
    write_results(args.out, results, RESULT_KEYS, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

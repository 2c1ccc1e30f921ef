"""Speed of the ``rsd_prior`` field model: its fit and prediction times on a sparse scan.

Capture: ``letter_t`` (64 x 64 sensors on a 2 m wall, 2048 bins of 3 mm, laser spot at the
centre), rendered by embree with Poisson noise (the default 1e6 photons), turned into 151
frequencies by the ``fft`` transform (default band 4-16 cycles/m) and split as the
pipeline does (every ``step``-th sample in x and y, every tenth frequency held out):
``step`` 4 (16 x 16, 16x fewer samples) and 8 (8 x 8, 64x). Per step: the fit's seconds
(the minimum of ``--repeats`` fits: the machine's cores are shared) and the prediction of
the full field's seconds.

How well ``rsd_prior`` images sparse scans (the judged scenes, timing jitter, calibration
errors) is a study: ``studies/physics_terms_measured`` (``run.py run --calibration``).

Results go to ``benchmarks/results/bench_rsd_prior.json``.

    python benchmarks/model/bench_rsd_prior.py [--repeats 2] [--cache DIR] [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, machine, write_results

from nlosfw.capture import Capture, read_capture, write_capture
from nlosfw.evaluation import split_field
from nlosfw.model import RSDPriorFieldModel
from nlosfw.plugins import load_plugins
from nlosfw.simulate import builtin_scene
from nlosfw.transform import FFTTransform

RESULTS = RESULTS_DIR / "bench_rsd_prior.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'machine', 'options', 'quick', 'timing')
SCENE, SIMULATOR = "letter_t", "embree"


def capture_for(cache: Path | None, quick: bool) -> Capture:
    """The benchmark's capture (the clean render cached in ``cache``), with Poisson noise."""
    host = load_plugins()
    overrides: dict[str, Any] = {}
    if quick:
        overrides = {"wall": {"resolution": [32, 32]}, "time": {"bins": 1024,
                                                               "bin_width": 0.006}}
    scene = builtin_scene(SCENE, **overrides)
    sim = host.registry.create("simulator", SIMULATOR, {"samples": 32768} if quick else {})
    path = None if cache is None else cache / f"{SCENE}-{SIMULATOR}-{quick}.hdf5"
    if path is not None and path.exists():
        clean = read_capture(path)
    else:
        clean = sim.simulate_clean(scene)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_capture(path, clean)
    return sim.add_noise(clean, builtin_scene(SCENE, **overrides, noise={"model": "poisson"}))


def timing(cache: Path | None, quick: bool, repeats: int, options: dict[str, Any]
           ) -> dict[str, Any]:
    """Per spatial step: the fit's seconds (each of ``repeats`` and their minimum), the
    training field's shape, the depth planes fitted and the prediction's seconds."""
    capture = capture_for(cache, quick)
    field = FFTTransform({"n_frequencies": 61 if quick else 151}).transform(capture)
    out: dict[str, Any] = {"case": f"{SCENE}/{SIMULATOR}/poisson"}
    for step in (4, 8):
        split = split_field(field, spatial_step=step)
        seconds = []
        for _ in range(repeats):
            model = RSDPriorFieldModel(options)
            start = time.perf_counter()
            model.fit(split.train_field)
            seconds.append(time.perf_counter() - start)
        start = time.perf_counter()
        model.predict(field.wall_xyz[..., :2], field.frequencies)
        predict_s = time.perf_counter() - start
        out[str(step)] = {"fit_s_min": min(seconds), "fit_s": seconds,
                          "train_shape": list(split.train_field.values.shape),
                          "planes": int(model.lattice.depths.size), "predict_s": predict_s}
        print(f"timing step {step}: fit {min(seconds):.1f} s (min of {repeats}) on "
              f"{split.train_field.values.shape}, {model.lattice.depths.size} planes; "
              f"predict {predict_s:.1f} s", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cache", type=Path, default=None,
                        help="directory for the clean render (reused between runs)")
    parser.add_argument("--quick", action="store_true", help="32 x 32 smoke run")
    parser.add_argument("--repeats", type=int, default=2, help="fits per step")
    parser.add_argument("--options", default="{}", help="rsd_prior options as JSON")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    options = json.loads(args.options)
    results: dict[str, Any] = {
        "benchmark": "bench_rsd_prior", "quick": args.quick, "options": options,
        "machine": machine(numpy=np.__version__),
        "timing": timing(args.cache, args.quick, args.repeats, options),
    }
    write_results(args.out, results, RESULT_KEYS)
    print(f"\nwritten: {args.out}")


if __name__ == "__main__":
    main()

"""Speed of the field models: six neural fields and ``interp`` on the thesis split.

Data: the ``thesis_two_planes`` scene (two rectangles at two depths, 64 x 64
sensors on a 2 m wall, 2048 bins of 3 mm) rendered by the ``analytic``
simulator, clean and with Poisson noise (``--photons`` expected signal photons),
turned into 151 frequencies by the ``fft`` transform with its default band
(f_max = 1/(2 x spacing), f_min = f_max / 4; a numpy DFT when that transform is
not installed). Protocol: :func:`nlosfw.evaluation.split_field` (every other wall
sample, 10% of the frequencies interleaved), i.e. 32 x 32 x 135 training samples.

For every model (default configs; ``--models`` to choose): training wall-clock
time, the training loss against training time (at every progress report), the
time to predict the full 64 x 64 x 151 field, and parameters/data as in thesis
Table 4.1. Torch vs JAX speed is reported as a ratio of milliseconds per step.
Results go to ``benchmarks/results/bench_field_models.json``.

How well the models predict the held-out samples of this split is a study:
``studies/thesis_reproduction`` (``run.py run --field-models``).

    python benchmarks/model/bench_field_models.py [--quick] [--models siren_torch,interp]
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

from nlosfw.evaluation import FieldSplit, parameter_data_ratio, split_field
from nlosfw.model import TrainingStep
from nlosfw.plugins import load_plugins
from nlosfw.simulate import AnalyticSimulator, Scene, scene_from_config
from nlosfw.transform import PhasorField

RESULTS = RESULTS_DIR / "bench_field_models.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('machine', 'n_frequencies', 'photons', 'quick', 'resolution', 'targets',
               'torch_over_jax_ms_per_step', 'variants')
MODELS = ("interp", "interp_raw", "siren_torch", "siren_jax", "pe_torch", "pe_jax", "tanh_torch",
          "tanh_jax")
#: Benchmark entries that are a registered model with options: label -> (name, options).
VARIANTS = {"interp_raw": ("interp", {"demodulate": False})}
TARGETS = {"siren_torch_fit_s": 60.0, "predict_s": 0.5}

#: Fallback when the scene file is not installed: two rectangles at two depths.
INLINE_SCENE = {
    "name": "two_planes_inline",
    "wall": {"size": [2.0, 2.0], "resolution": [64, 64]},
    "capture": {"type": "single_spot"},
    "time": {"bins": 2048, "bin_width": 0.003, "start": 0.0},
    "geometry": [
        {"type": "rectangle", "position": [0.55, 0.1, 1.0], "size": [0.4, 0.6]},
        {"type": "rectangle", "position": [-0.45, -0.1, 1.4], "size": [0.5, 0.8]},
    ],
}


def bench_scene(resolution: int, photons: float | None) -> Scene:
    """thesis_two_planes (or the inline fallback) at ``resolution``^2, optionally noisy."""
    noise = {"model": "poisson", "photons": photons} if photons else {"model": "none"}
    overrides = {"wall": {"resolution": [resolution, resolution]}, "noise": noise}
    try:
        from nlosfw.simulate import builtin_scene

        return builtin_scene("thesis_two_planes", **overrides)
    except Exception:  # scene files not installed: same layout, inline
        config = {**INLINE_SCENE, **overrides,
                  "wall": {**INLINE_SCENE["wall"], **overrides["wall"]}}
        return scene_from_config(config)


def to_field(capture: Any, n_frequencies: int) -> PhasorField:
    """The ``fft`` transform with its default band, or a plain numpy DFT of the same band."""
    try:
        from nlosfw.transform import FFTTransform

        return FFTTransform({"n_frequencies": n_frequencies}).transform(capture)
    except ImportError:
        spacing = float(np.abs(capture.sensor_grid_xyz[1, 0, 0] - capture.sensor_grid_xyz[0, 0, 0]))
        f = np.linspace(0.25 / (2 * spacing), 1 / (2 * spacing), n_frequencies)
        t = capture.t_start + (np.arange(capture.n_bins) + 0.5) * capture.delta_t
        kernel = np.exp(-2j * np.pi * np.outer(f, t)) * capture.delta_t
        values = np.tensordot(kernel, capture.H.astype(np.float64), axes=(1, 0))   # (F, X, Y)
        return PhasorField(values=np.transpose(values, (0, 2, 1)), frequencies=f,
                           wall_xyz=np.transpose(capture.sensor_grid_xyz, (1, 0, 2)),
                           geometry=capture.geometry)


def run_model(registry: Any, name: str, options: dict[str, Any], split: FieldSplit,
              full: PhasorField) -> dict[str, Any]:
    """Train one model on ``split``; time its fit and its prediction of ``full``'s grid."""
    model = registry.create("model", name, options)
    xy = full.wall_xyz[..., :2]
    curve: list[dict[str, float]] = []

    def on_step(step: TrainingStep) -> None:
        curve.append({"step": step.step, "seconds": step.seconds, "loss": step.loss})

    start = time.perf_counter()
    report = model.fit(split.train_field, on_step=None if name == "interp" else on_step)
    fit_seconds = time.perf_counter() - start
    predict_seconds = []
    for _ in range(3):
        t0 = time.perf_counter()
        model.predict(xy, full.frequencies)
        predict_seconds.append(time.perf_counter() - t0)
    n_params = int(model.n_parameters)
    return {
        "model": name, "options": options, "fit_s": fit_seconds, "steps": report.steps,
        "ms_per_step": 1000 * fit_seconds / max(report.steps, 1),
        "predict_s": min(predict_seconds), "n_parameters": n_params,
        "parameters_per_data_pct": parameter_data_ratio(n_params, split), "curve": curve,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small smoke run")
    parser.add_argument("--models", default=",".join(MODELS))
    parser.add_argument("--photons", type=float, default=1e6,
                        help="expected signal photons of the noisy capture (Poisson)")
    parser.add_argument("--variants", default="clean,noisy")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--update", action="store_true",
                        help="keep the rows of other models from an existing --out file")
    args = parser.parse_args()

    resolution, n_freq = (32, 41) if args.quick else (64, 151)
    quick_options = {"steps": 150, "eval_every": 50} if args.quick else {}
    registry = load_plugins().registry
    names = [n for n in args.models.split(",") if n]
    results: dict[str, Any] = {
        "machine": machine(),
        "quick": args.quick, "resolution": resolution, "n_frequencies": n_freq,
        "photons": args.photons, "targets": TARGETS, "variants": {},
    }
    for variant in args.variants.split(","):
        scene = bench_scene(resolution, args.photons if variant == "noisy" else None)
        t0 = time.perf_counter()
        capture = AnalyticSimulator({"patch_size": 0.02}).simulate(scene)
        field = to_field(capture, n_freq)
        split = split_field(field, spatial_step=2, spectral="interleaved")
        rows = []
        for label in names:
            name, options = VARIANTS.get(label, (label, {}))
            spec = registry.get("model", name) if ("model", name) in registry else None
            if spec is None or spec.install_command():
                print(f"skipping {label}: not installed")
                continue
            options = dict(options) if name == "interp" else {**options, **quick_options}
            rows.append(run_model(registry, name, options, split, field))
            r = rows[-1]
            r["model"] = label
            print(f"{variant:5s} {label:12s} fit {r['fit_s']:6.1f} s  "
                  f"predict {r['predict_s']:.2f} s", flush=True)
        results["variants"][variant] = {
            "data_seconds": time.perf_counter() - t0,
            "band": [float(field.frequencies.min()), float(field.frequencies.max())],
            "train_values": split.n_train_values, "models": rows,
        }
    if args.update and args.out.is_file():
        merge_previous(results, json.loads(args.out.read_text()))
    results["torch_over_jax_ms_per_step"] = speed_ratios(results)
    print_tables(results)
    write_results(args.out, results, RESULT_KEYS, indent=1)
    print(f"wrote {args.out}")


def merge_previous(results: dict[str, Any], previous: dict[str, Any]) -> None:
    """Add the rows of models not re-run from ``previous`` (same variants), in MODELS order."""
    for variant, data in results["variants"].items():
        old = previous.get("variants", {}).get(variant)
        if not old:
            continue
        rows = {r["model"]: r for r in old["models"]}
        rows.update({r["model"]: r for r in data["models"]})
        order = {m: i for i, m in enumerate(MODELS)}
        data["models"] = sorted(rows.values(), key=lambda r: order.get(r["model"], 99))


def speed_ratios(results: dict[str, Any]) -> dict[str, float]:
    """ms/step of torch over JAX per family and variant (> 1: JAX is faster)."""
    ratios = {}
    for variant, data in results["variants"].items():
        rows = {r["model"]: r for r in data["models"]}
        for family in ("tanh", "pe", "siren"):
            t, j = rows.get(f"{family}_torch"), rows.get(f"{family}_jax")
            if t and j:
                ratios[f"{variant}:{family}"] = t["ms_per_step"] / j["ms_per_step"]
    return ratios


def print_tables(results: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=170)
    for variant, data in results["variants"].items():
        table = Table(title=f"field models, {variant} capture")
        for col in ("model", "params", "params/data %", "fit s", "ms/step", "predict s"):
            table.add_column(col, justify="right")
        for r in data["models"]:
            table.add_row(r["model"], str(r["n_parameters"]),
                          f"{r['parameters_per_data_pct']:.2f}", f"{r['fit_s']:.1f}",
                          "-" if r["model"].startswith("interp") else f"{r['ms_per_step']:.1f}",
                          f"{r['predict_s']:.2f}")
        console.print(table)
    if results["torch_over_jax_ms_per_step"]:
        console.print("torch / JAX ms per step: " + ", ".join(
            f"{k} {v:.2f}" for k, v in results["torch_over_jax_ms_per_step"].items()))


if __name__ == "__main__":
    main()

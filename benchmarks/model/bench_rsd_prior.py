"""Benchmark of the ``rsd_prior`` field model: sparse scans, judged on the image.

Scenes (64 x 64 sensors on a 2 m wall, 2048 bins of 3 mm, laser spot at the centre),
each turned into 151 frequencies by the ``fft`` transform (default band 4-16 cycles/m)
and split as the pipeline does (every ``step``-th sample in x and y, every tenth
frequency held out): ``step`` 4 (16 x 16, 16x fewer samples) and 8 (8 x 8, 64x).

Sources, all imaged by the ``fft`` imager on the pipeline's default voxels (24 planes
spanning the true depths with a margin, the whole wall's width at the wall spacing):
the full capture (the reference), the sparse samples imaged directly (``raw``),
``interp`` and ``rsd_prior`` (its default config) upsampled to the full grid.

Scores of each source against the reference, the run's own
(:func:`nlosfw.evaluation.reconstruction_scores`): amplitudes = sqrt(intensity), each
normalised to its maximum; ``psnr`` and ``ssim`` of the front-view maximum projections
and ``volume_psnr`` / ``volume_ssim`` of the whole volumes (scikit-image
``peak_signal_noise_ratio(a, b, data_range=1)`` and ``structural_similarity(a, b,
data_range=1)`` at their defaults); ``depth_rmse_m``: the depth of the brightest voxel of
each (y, x) column against the scene's true depth map, over the pixels where it has a
surface (the reference's own value is listed too; None where such a column is dark).

Case groups (``--cases``, comma-separated):

* ``tuning``: thesis_planes and thesis_concave, analytic and embree + Poisson (the only
  scenes defaults were tuned on);
* ``judged``: letter_t and thesis_two_planes noise-free (analytic) and noisy (embree,
  Poisson, the default 1e6 photons), thesis_occluded noisy (embree, Poisson);
* ``robustness``: letter_t and thesis_two_planes (embree, Poisson) at step 4 with timing
  jitter of 50 and 100 ps, the capture's time origin off by +1 cm of path, and the laser
  spot off by 1 cm in x. Calibration errors are in the capture every stage reads (the
  transform, the models and the imager): the reference is the full capture with the same
  error, and ``depth_rmse_m`` measures what the error costs against the truth;
* ``timing``: rsd_prior's fit time at steps 4 and 8 (151 frequencies, 135 fitted), the
  minimum of ``--repeats`` fits (the machine's cores are shared).

Results go to ``benchmarks/results/bench_rsd_prior.json``.

    python benchmarks/model/bench_rsd_prior.py [--cases judged,robustness] [--cache DIR] [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, machine, write_results

from nlosfw.capture import Capture, read_capture, write_capture
from nlosfw.evaluation import depth_rmse, error_metrics, reconstruction_scores, split_field
from nlosfw.image import FFTImager, Reconstruction, volume_voxels
from nlosfw.model import InterpFieldModel, RSDPriorFieldModel
from nlosfw.plugins import load_plugins
from nlosfw.simulate import builtin_scene
from nlosfw.transform import FFTTransform, PhasorField

RESULTS = RESULTS_DIR / "bench_rsd_prior.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'cases', 'groups', 'machine', 'options', 'quick')
#: Keys written only by some modes.
OPTIONAL_KEYS = ('timing',)
SOURCES = ("raw", "interp", "rsd_prior")
SCORES = ("psnr", "ssim", "volume_psnr", "volume_ssim", "depth_rmse_m")


@dataclass(frozen=True)
class Case:
    """One capture and how it is perturbed."""

    scene: str
    simulator: str = "analytic"
    noise: str = "none"
    jitter_ps: float = 0.0
    calibration: str = ""          # "", "t_start+1cm" or "laser_x+1cm"
    steps: tuple[int, ...] = (4, 8)

    @property
    def label(self) -> str:
        parts = [self.scene, self.simulator, self.noise]
        if self.jitter_ps:
            parts.append(f"jitter{self.jitter_ps:g}ps")
        if self.calibration:
            parts.append(self.calibration)
        return "/".join(parts)


def cases(groups: list[str]) -> list[Case]:
    out: list[Case] = []
    if "tuning" in groups:
        for scene in ("thesis_planes", "thesis_concave"):
            out += [Case(scene), Case(scene, "embree", "poisson")]
    if "judged" in groups:
        for scene in ("letter_t", "thesis_two_planes"):
            out += [Case(scene), Case(scene, "embree", "poisson")]
        out.append(Case("thesis_occluded", "embree", "poisson"))
    if "robustness" in groups:
        for scene in ("letter_t", "thesis_two_planes"):
            base = Case(scene, "embree", "poisson", steps=(4,))
            out += [Case(scene, "embree", "poisson", jitter_ps=50.0, steps=(4,)),
                    Case(scene, "embree", "poisson", jitter_ps=100.0, steps=(4,)),
                    Case(scene, "embree", "poisson", calibration="t_start+1cm", steps=(4,)),
                    Case(scene, "embree", "poisson", calibration="laser_x+1cm", steps=(4,))]
            if "judged" not in groups:
                out.insert(len(out) - 4, base)
    return out


# ------------------------------------------------------------------ captures
def capture_for(case: Case, cache: Path | None, quick: bool) -> tuple[Capture, float]:
    """The case's capture (clean renders cached in ``cache``) and the render seconds."""
    host = load_plugins()
    overrides: dict[str, Any] = {}
    if quick:
        overrides = {"wall": {"resolution": [32, 32]}, "time": {"bins": 1024,
                                                               "bin_width": 0.006}}
    scene = builtin_scene(case.scene, **overrides)
    sim = host.registry.create("simulator", case.simulator,
                               {"samples": 32768} if quick and case.simulator == "embree" else {})
    path = None if cache is None else cache / f"{case.scene}-{case.simulator}-{quick}.hdf5"
    start = time.perf_counter()
    if path is not None and path.exists():
        clean = read_capture(path)
    else:
        clean = sim.simulate_clean(scene)
        if path is not None:
            cache.mkdir(parents=True, exist_ok=True)
            write_capture(path, clean)
    seconds = time.perf_counter() - start
    noisy = builtin_scene(case.scene, **overrides,
                          noise={"model": case.noise, "jitter_ps": case.jitter_ps})
    capture = sim.add_noise(clean, noisy)
    return miscalibrated(capture, case.calibration), seconds


def miscalibrated(capture: Capture, calibration: str) -> Capture:
    """The capture with a wrong time origin or laser spot (what every stage then reads)."""
    if calibration == "t_start+1cm":
        return capture.replace(t_start=capture.t_start + 0.01)
    if calibration == "laser_x+1cm":
        laser = np.array(capture.laser_grid_xyz, dtype=float)
        laser[..., 0] += 0.01
        return capture.replace(laser_grid_xyz=laser)
    return capture


def default_voxels(capture: Capture, field: PhasorField, n_depths: int = 24) -> np.ndarray:
    """The pipeline's default voxels: 24 planes over the true depths (margin max(0.15 m,
    25% of their span)), the whole wall's width at the wall spacing."""
    depth = np.asarray(capture.scene_info["ground_truth"]["depth"], dtype=float)
    hit = depth[depth > 0]
    lo, hi = float(hit.min()), float(hit.max())
    margin = max(0.15, 0.25 * (hi - lo))
    depths = np.linspace(max(0.05, lo - margin), hi + margin, n_depths)
    dy, dx = field.grid_spacing()
    ny, nx = field.grid_shape
    x0, y0 = field.wall_xyz[0, 0, 0] - dx / 2, field.wall_xyz[0, 0, 1] - dy / 2
    return volume_voxels(depths, (x0, x0 + nx * dx), (y0, y0 + ny * dy), (ny, nx))


def true_depth(capture: Capture) -> np.ndarray:
    """The scene's depth map on the wall grid as (Y, X) (-1: no surface)."""
    return np.asarray(capture.scene_info["ground_truth"]["depth"], dtype=float).T


# ------------------------------------------------------------------ scores
def scores(reference: Reconstruction, test: Reconstruction,
           truth: np.ndarray) -> dict[str, float | None]:
    """The run's reconstruction scores of ``test`` against ``reference``
    (:func:`nlosfw.evaluation.reconstruction_scores`, ``rmse`` left out)."""
    values = reconstruction_scores(reference, test, truth)
    return {name: values[name] for name in SCORES}


def _shown(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


# ------------------------------------------------------------------ runs
def run_case(case: Case, cache: Path | None, quick: bool, options: dict[str, Any]
             ) -> dict[str, Any]:
    capture, render_s = capture_for(case, cache, quick)
    field = FFTTransform({"n_frequencies": 61 if quick else 151}).transform(capture)
    voxels = default_voxels(capture, field)
    truth = true_depth(capture)
    imager = FFTImager({"workers": -1})
    reference = imager.reconstruct(field, voxels)
    out: dict[str, Any] = {"case": case.label, "render_s": render_s,
                           "reference_depth_rmse_m": depth_rmse(reference, truth),
                           "steps": {}}
    for step in case.steps:
        split = split_field(field, spatial_step=step)
        xy = field.wall_xyz[..., :2]
        fields: dict[str, PhasorField] = {
            "raw": field.select(y=slice(None, None, step), x=slice(None, None, step))}
        fit_s: dict[str, float] = {}
        info: dict[str, Any] = {}
        for name, model in (("interp", InterpFieldModel()),
                            ("rsd_prior", RSDPriorFieldModel(options))):
            start = time.perf_counter()
            report = model.fit(split.train_field)
            fit_s[name] = time.perf_counter() - start
            fields[name] = model.predict_field(field.wall_xyz, field.frequencies, field.geometry,
                                               field.weights)
            if name == "rsd_prior":
                assert isinstance(model, RSDPriorFieldModel)
                info = {"planes": int(model.lattice.depths.size),
                        "voxels": int(model.n_parameters),
                        "nonzero": int(np.count_nonzero(model.albedo)),
                        "residual": float(report.final_loss)}
        row: dict[str, Any] = {"fit_s": fit_s, "rsd_prior": info, "scores": {}}
        for name in SOURCES:
            recon = imager.reconstruct(fields[name], voxels)
            row["scores"][name] = scores(reference, recon, truth)
        field_err = {name: error_metrics(field.values, fields[name].values)["relative_l2"]
                     for name in ("interp", "rsd_prior")}
        row["field_relative_l2"] = field_err
        out["steps"][str(step)] = row
        s = row["scores"]
        print(f"{case.label:45s} step {step}: " + "  ".join(
            f"{n} {_shown(s[n]['psnr'], '5.1f')} dB {_shown(s[n]['ssim'], '.3f')} "
            f"{_shown(s[n]['depth_rmse_m'], '.3f')} m"
            for n in SOURCES) + f"  (fit {fit_s['rsd_prior']:.0f} s, ref depth "
            f"{_shown(out['reference_depth_rmse_m'], '.3f')} m)", flush=True)
        del xy
    return out


def timing(cache: Path | None, quick: bool, repeats: int, options: dict[str, Any]
           ) -> dict[str, Any]:
    case = Case("letter_t", "embree", "poisson")
    capture, _ = capture_for(case, cache, quick)
    field = FFTTransform({"n_frequencies": 61 if quick else 151}).transform(capture)
    out: dict[str, Any] = {"case": case.label}
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


def table(results: dict[str, Any]) -> str:
    lines = ["| case | step | source | PSNR dB | SSIM | vol PSNR | vol SSIM | depth RMSE m | "
             "fit s |", "|---|---|---|---|---|---|---|---|---|"]
    for entry in results["cases"]:
        for step, row in entry["steps"].items():
            for name in SOURCES:
                s = row["scores"][name]
                fit = row["fit_s"].get(name)
                lines.append(
                    f"| {entry['case']} | {step} | {name} | {s['psnr']:.1f} | {s['ssim']:.3f} | "
                    f"{s['volume_psnr']:.1f} | {s['volume_ssim']:.3f} | "
                    f"{s['depth_rmse_m']:.3f} (ref {entry['reference_depth_rmse_m']:.3f}) | "
                    f"{'' if fit is None else f'{fit:.1f}'} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default="judged,robustness,timing",
                        help="comma-separated groups: tuning, judged, robustness, timing")
    parser.add_argument("--cache", type=Path, default=None,
                        help="directory for the clean renders (reused between runs)")
    parser.add_argument("--quick", action="store_true", help="32 x 32 smoke run")
    parser.add_argument("--repeats", type=int, default=2, help="fits per timing")
    parser.add_argument("--options", default="{}", help="rsd_prior options as JSON")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    groups = [g for g in args.cases.split(",") if g]
    options = json.loads(args.options)
    results: dict[str, Any] = {
        "benchmark": "bench_rsd_prior", "quick": args.quick, "groups": groups,
        "options": options,
        "machine": machine(numpy=np.__version__),
        "cases": [],
    }
    for case in cases(groups):
        results["cases"].append(run_case(case, args.cache, args.quick, options))
    if "timing" in groups:
        results["timing"] = timing(args.cache, args.quick, args.repeats, options)
    print()
    print(table(results))
    write_results(args.out, results, RESULT_KEYS, OPTIONAL_KEYS)
    print(f"\nwritten: {args.out}")


if __name__ == "__main__":
    main()

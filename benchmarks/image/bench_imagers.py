"""Benchmark of the phasor-field imagers: ``fft`` and ``rsd`` side by side.

A 64 x 64 single-spot capture of a 2 m wall (2048 bins) from the analytic
simulator (a tilted rectangle, two patches and a point), the ``wavelet``
transform with its default settings (lambda_c = 4 x spacing, 5 cycles; the bin
width is chosen so that it keeps about 90 frequencies), then:

* ``fft``: one depth plane and a 64-plane volume (64 x 64 voxels per plane);
* ``rsd``: a few planes, extrapolated to the 64^3 volume (``--full-rsd`` runs it all);
* y-tal's ``tal.reconstruct.pf_dev`` on the same capture (written with
  ``nlosfw.capture.write_capture``) for one plane, when ``$NLOSFW_YTAL_PYTHON`` (default
  ``/tmp/ytal-venv/bin/python``) exists, in a subprocess; our time is reported as a ratio
  against it.

Times are wall-clock seconds (best of ``--repeat`` for single planes); peak
memory is the largest traced numpy/Python allocation (tracemalloc) of a
separate run. Results go to ``benchmarks/results/bench_imagers.json``.

    python benchmarks/image/bench_imagers.py [--quick] [--full-rsd]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, best_of, write_results

from nlosfw.image import FFTImager, RSDImager, volume_voxels
from nlosfw.simulate import AnalyticSimulator, scene_from_config
from nlosfw.transform import WaveletTransform

#: A Python with y-tal (it pins numpy<2: keep it in its own venv, never a dependency).
YTAL_PYTHON = Path(os.environ.get("NLOSFW_YTAL_PYTHON", "/tmp/ytal-venv/bin/python"))
RESULTS = RESULTS_DIR / "bench_imagers.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'capture', 'fft_vs_rsd', 'imagers', 'machine', 'quick', 'targets',
               'voxels', 'wavelet', 'ytal_pf_dev')
TARGETS = {"fft_plane_s": 0.15, "fft_volume_s": 8.0, "rsd_volume_peak_mb": 4096.0}

YTAL_SCRIPT = r"""
import json, sys, time
import numpy as np
import tal
from tal.enums import CameraSystem, VolumeFormat
path, out, wl_mean, wl_sigma, depth = sys.argv[1], sys.argv[2], *map(float, sys.argv[3:6])
data = tal.io.read_capture(path)
grid = np.asarray(data.sensor_grid_xyz)                  # (X, Y, 3)
volume = grid.copy()
volume[..., 2] = depth
times = []
for _ in range(int(sys.argv[6])):
    t0 = time.perf_counter()
    image = tal.reconstruct.pf_dev.solve(data, wl_mean, wl_sigma, volume_xyz=volume,
                                         volume_format=VolumeFormat.X_Y_3,
                                         camera_system=CameraSystem.DIRECT_LIGHT, progress=False,
                                         nt=data.H.shape[0])  # y-tal 0.20 needs nt given
    times.append(time.perf_counter() - t0)
np.save(out, np.abs(np.asarray(image)) ** 2)
print(json.dumps({"seconds": min(times), "all": times, "version": tal.__version__}))
"""


def scene_config(n: int, bins: int, bin_width: float) -> dict[str, Any]:
    """64 x 64 sensors on a 2 m wall, laser at the centre, a few hidden items."""
    return {
        "name": "bench_imagers",
        "wall": {"size": [2.0, 2.0], "resolution": [n, n]},
        "capture": {"type": "single_spot"},
        "time": {"bins": bins, "bin_width": bin_width, "start": 0.0},
        "geometry": [
            {"type": "rectangle", "position": [-0.3, 0.2, 1.0], "size": [0.4, 0.3],
             "rotation": [0.0, 20.0, 0.0]},
            {"type": "patch", "position": [0.4, -0.3, 1.3], "size": [0.1, 0.1]},
            {"type": "patch", "position": [0.1, 0.5, 0.8], "size": [0.08, 0.08]},
            {"type": "point", "position": [0.5, 0.4, 1.5], "albedo": 0.01},
        ],
    }


def peak_mb(fn: Callable[[], Any]) -> float:
    """Peak traced allocation (MiB) while ``fn`` runs."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def run_ytal(capture: Any, wavelength: float, sigma: float, depth: float,
             repeat: int) -> dict[str, Any] | None:
    """Time y-tal's pf_dev on one plane in its own venv; None when y-tal is absent."""
    if not YTAL_PYTHON.exists():
        return None
    from nlosfw import write_capture

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "capture.hdf5"
        write_capture(path, capture)
        script = Path(tmp) / "run_ytal.py"
        script.write_text(YTAL_SCRIPT)
        out = Path(tmp) / "ytal.npy"
        env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
        result = subprocess.run(
            [str(YTAL_PYTHON), str(script), str(path), str(out), str(wavelength), str(sigma),
             str(depth), str(repeat)],
            capture_output=True, text=True, timeout=900, env=env, check=False)
        if result.returncode != 0:
            return {"error": result.stderr.strip().splitlines()[-1:] or ["failed"]}
        info = json.loads(result.stdout.strip().splitlines()[-1])
        info["image"] = np.load(out)                          # (X, Y)
        return info


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    a = a.ravel() - a.mean()
    b = b.ravel() - b.mean()
    return float(a @ b / np.sqrt((a @ a) * (b @ b)))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small smoke run (16 planes)")
    parser.add_argument("--full-rsd", action="store_true", help="run rsd on the whole volume")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)

    n, bins, bin_width = 64, 2048, 0.0045
    n_planes = 16 if args.quick else 64
    rsd_planes = 1 if args.quick else 2
    depths = np.linspace(0.5, 2.0, n_planes)
    plane_depth = 1.0

    t0 = time.perf_counter()
    scene = scene_from_config(scene_config(n, bins, bin_width))
    capture = AnalyticSimulator({"patch_size": 0.02}).simulate(scene)
    t_sim = time.perf_counter() - t0
    transform = WaveletTransform()
    t_transform, field = best_of(lambda: transform.transform(capture), args.repeat)
    wavelet = field.metadata["wavelet"]
    extent = (-1.0, 1.0)
    volume = volume_voxels(depths, extent, extent, (n, n))
    plane = volume_voxels([plane_depth], extent, extent, (n, n))[0]
    fft, rsd = FFTImager(), RSDImager()

    rows: dict[str, Any] = {}
    t, fft_plane = best_of(lambda: fft.reconstruct(field, plane), args.repeat)
    rows["fft_plane"] = {"seconds": t, "peak_mb": peak_mb(lambda: fft.reconstruct(field, plane))}
    t, _ = best_of(lambda: fft.reconstruct(field, volume))
    rows["fft_volume"] = {"seconds": t, "planes": n_planes,
                          "peak_mb": peak_mb(lambda: fft.reconstruct(field, volume))}
    t, rsd_plane = best_of(lambda: rsd.reconstruct(field, plane))
    rows["rsd_plane"] = {"seconds": t, "peak_mb": peak_mb(lambda: rsd.reconstruct(field, plane))}
    sub = volume[:rsd_planes]
    if args.full_rsd:                      # one traced run gives both time and peak memory
        tracemalloc.start()
        t, _ = best_of(lambda: rsd.reconstruct(field, volume))
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        rows["rsd_volume"] = {"seconds": t, "planes": n_planes, "extrapolated": False,
                              "peak_mb": peak, "note": "timed with tracemalloc running"}
    else:
        t, _ = best_of(lambda: rsd.reconstruct(field, sub))
        rows["rsd_volume"] = {"seconds": t * n_planes / rsd_planes, "planes": n_planes,
                              "extrapolated": True, "measured_planes": rsd_planes,
                              "measured_seconds": t,
                              "peak_mb": peak_mb(lambda: rsd.reconstruct(field, sub))}
        rows["rsd_volume"]["peak_mb_note"] = (
            "peak of the measured planes; rsd works in fixed voxel blocks, so a larger volume "
            "adds only its output (64^3: 2 MiB) to it")
    agreement = correlation(fft_plane.intensity, rsd_plane.intensity)
    max_rel = float(np.max(np.abs(fft_plane.intensity - rsd_plane.intensity))
                    / np.max(rsd_plane.intensity))

    ytal = run_ytal(capture, wavelet["wavelength"], wavelet["sigma"], plane_depth, args.repeat)
    ytal_row: dict[str, Any] = {"available": ytal is not None}
    if ytal is not None and "error" not in ytal:
        ours_xy = fft_plane.intensity.T                        # (Y, X) -> (X, Y) like y-tal
        ytal_row.update({"seconds": ytal["seconds"], "version": ytal["version"],
                         "fft_speedup": ytal["seconds"] / rows["fft_plane"]["seconds"],
                         "correlation_with_fft": correlation(ours_xy, ytal["image"])})
    elif ytal is not None:
        ytal_row["error"] = ytal["error"]

    results = {
        "benchmark": "bench_imagers",
        "quick": args.quick,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__},
        "capture": {"sensors": [n, n], "wall_m": 2.0, "bins": bins, "bin_width_m": bin_width,
                    "kind": "single_spot", "simulate_seconds": t_sim},
        "wavelet": {"n_frequencies": int(field.n_frequencies),
                    "wavelength_m": wavelet["wavelength"], "sigma_m": wavelet["sigma"],
                    "transform_seconds": t_transform, "method": field.metadata["method"]},
        "voxels": {"plane": [n, n], "volume": [n_planes, n, n],
                   "depths_m": [float(depths[0]), float(depths[-1])]},
        "imagers": rows,
        "fft_vs_rsd": {"correlation": agreement, "max_relative_difference": max_rel},
        "ytal_pf_dev": ytal_row,
        "targets": TARGETS,
    }
    report(results)
    write_results(RESULTS, results, RESULT_KEYS)
    return results


def report(results: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    rows = results["imagers"]
    ytal = results["ytal_pf_dev"]
    table = Table(title=(f"phasor imagers: 64x64 wall, {results['capture']['bins']} bins, "
                         f"{results['wavelet']['n_frequencies']} frequencies "
                         f"({results['machine']['cpus']} cores)"))
    for col in ("case", "fft s", "rsd s", "fft peak MiB", "rsd peak MiB", "target"):
        table.add_column(col, justify="right" if col != "case" else "left")
    note = " (extrapolated)" if rows["rsd_volume"].get("extrapolated") else ""
    table.add_row("one plane 64x64", f"{rows['fft_plane']['seconds']:.3f}",
                  f"{rows['rsd_plane']['seconds']:.2f}", f"{rows['fft_plane']['peak_mb']:.0f}",
                  f"{rows['rsd_plane']['peak_mb']:.0f}", "fft <= 0.15 s")
    table.add_row(f"volume {rows['fft_volume']['planes']} planes",
                  f"{rows['fft_volume']['seconds']:.2f}",
                  f"{rows['rsd_volume']['seconds']:.0f}{note}",
                  f"{rows['fft_volume']['peak_mb']:.0f}", f"{rows['rsd_volume']['peak_mb']:.0f}",
                  "fft <= 8 s, rsd <= 4096 MiB")
    if ytal.get("seconds") is not None:
        table.add_row("y-tal pf_dev, one plane", f"{ytal['seconds']:.3f}", "", "", "",
                      f"fft {ytal['fft_speedup']:.1f}x faster")
    console = Console(width=120)
    console.print(table)
    agree = results["fft_vs_rsd"]
    extra = ""
    if ytal.get("correlation_with_fft") is not None:
        extra = f"; y-tal image vs fft correlation {ytal['correlation_with_fft']:.4f}"
    elif not ytal.get("available"):
        extra = "; y-tal not found (skipped)"
    console.print(f"transform {results['wavelet']['transform_seconds']:.3f} s "
                    f"({results['wavelet']['method']}); fft vs rsd on the plane: correlation "
                    f"{agree['correlation']:.6f}, max relative difference "
                    f"{agree['max_relative_difference']:.2e}{extra}")


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

"""The FFT-based imagers (fft, lct, fk, fbp) per device: seconds per reconstruction.

Each imager reconstructs a closed-form confocal point scatterer's field (64 x 64 wall,
0.7 m, 151 frequencies up to 60 cycles/m, 96 planes at 0.3-0.8 m) with its numpy code
(``device=cpu``), with its device code on torch's CPU device (the code a GPU runs, on the
CPU: a check of the path, not a speed anyone should use) and on CUDA when torch sees a
device. Each keeps the least of ``--repeat`` runs after one warm-up (CUDA: synchronised,
the warm-up pays for the kernels' compilation and the plans), and the device images'
largest difference from numpy's, over numpy's peak.

Results go to ``benchmarks/results/bench_imager_devices.json`` with the machine.

    python benchmarks/image/bench_imager_devices.py [--repeat N] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, machine, write_results

RESULTS = RESULTS_DIR / "bench_imager_devices.json"
RESULT_KEYS = ("benchmark", "case", "timing", "machine", "imagers")
IMAGERS = ("fft", "lct", "fk", "fbp")


def point_case(quick: bool) -> tuple[Any, np.ndarray]:
    """(field, voxels) of the benchmark (a quarter of it with ``--quick``)."""
    n, freqs, planes = (32, 61, 24) if quick else (64, 151, 96)
    field = fixtures.point_field((0.05, -0.03, 0.55), (n, n), 0.7 / n,
                                 np.linspace(60.0 / freqs, 60.0, freqs), confocal=True)
    return field, fixtures.aligned_voxels(field.wall_xyz, np.linspace(0.3, 0.8, planes))


def timed(imager: Any, field: Any, voxels: np.ndarray, repeat: int,
          sync: Any = None) -> tuple[float, np.ndarray]:
    """(least seconds of ``repeat`` reconstructions after a warm-up, the image)."""
    image = imager.reconstruct(field, voxels).intensity
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        image = imager.reconstruct(field, voxels).intensity
        if sync is not None:
            sync()
        best = min(best, time.perf_counter() - start)
    return best, image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="a quarter-size field")
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args()
    import torch
    from nlosfw_torch.arrays import TorchArrays

    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    field, voxels = point_case(args.quick)
    registry = load_plugins().registry
    rows: dict[str, dict[str, Any]] = {}
    for name in IMAGERS:
        imager = registry.create("imager", name)
        numpy_s, reference = timed(imager, field, voxels, args.repeat)
        row: dict[str, Any] = {"numpy_s": round(numpy_s, 4)}
        for device in devices:
            sync = torch.cuda.synchronize if device == "cuda" else None
            seconds, image = timed(imager.on(TorchArrays(device)), field, voxels, args.repeat,
                                   sync)
            row[f"torch_{device}_s"] = round(seconds, 4)
            row[f"torch_{device}_max_difference"] = float(
                np.abs(image - reference).max() / np.abs(reference).max())
        rows[name] = row
    table = Table(title="seconds per reconstruction (least of the repeats)")
    for column in ("imager", "numpy (CPU)", *(f"torch {d}" for d in devices),
                   *(f"torch {d} vs numpy" for d in devices)):
        table.add_column(column, justify="right")
    for name, row in rows.items():
        table.add_row(name, f"{row['numpy_s']:.3f}",
                      *(f"{row[f'torch_{d}_s']:.3f}" for d in devices),
                      *(f"{row[f'torch_{d}_max_difference']:.1e}" for d in devices))
    Console(width=140).print(table)
    if args.no_save:
        return
    write_results(RESULTS, {
        "benchmark": "bench_imager_devices",
        "case": "confocal point scatterer, " + ("32 x 32, 61 frequencies, 24 planes"
                                                if args.quick else
                                                "64 x 64, 151 frequencies, 96 planes"),
        "timing": f"least of {args.repeat} after a warm-up",
        "machine": machine(torch=torch.__version__,
                           cuda=torch.cuda.get_device_name(0) if "cuda" in devices
                           else None),
        "imagers": rows,
    }, RESULT_KEYS)


if __name__ == "__main__":
    main()

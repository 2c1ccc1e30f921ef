"""Speed of the volume imagers against a per-plane baseline, and at real size.

Every ratio is against a baseline measured in the same process, on the same field:

* ``confocal``: the ``fft`` imager on a confocal field against a per-plane baseline,
  ``plain_minimum`` (one forward FFT per frequency; per plane, every frequency's spectrum
  times a depth-step propagator, a sum over frequencies with coefficients by ``einsum``,
  one inverse FFT and abs()^2: several times the minimal work, which
  ``bench_fft_minimum.py`` times instead), 64 x 64 (151 frequencies, 96 planes,
  128 x 128 padded) and 128 x 128 (128 planes, 256 x 256 padded);
* ``off the wall grid``: the confocal case with the voxel planes moved half a wall
  spacing (the general path; on the wall's own grid the kernel is even and its spectrum
  a quarter-size DCT);
* ``single_spot``: the same against its per-plane baseline (the laser leg differs per
  voxel and frequency: one inverse FFT per frequency and plane);
* ``real size``: a 64 x 64 x 2048 confocal capture (0.7 m scan, 4 ps bins from 0.2 m
  of path, a letter 0.9 m away), automatic band and depths: the transform plus ``fft``
  imaging, and the ``lct``, ``fk`` and ``fbp`` imagers on the same field and voxels.

The imager images depth planes on parallel threads (all cores); the plain minimum's
FFTs use every core too, its numpy products and sums one. The imager restricted to one
thread (``workers=1``) is timed beside it, with its ratio. ``error``: the largest
difference between the imager's image and the direct RSD sum (the ``rsd`` imager) at
256 voxels (the brightest and 255 random ones), relative to the image's maximum.

The machine's cores are shared, so each time is the minimum of ``--repeat`` runs.
Results go to ``benchmarks/results/bench_speed.json``.

    python benchmarks/image/bench_speed.py [--quick] [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
import scipy.fft
from harness import RESULTS_DIR, best_of, write_results

from nlosfw.image import FFTImager, RSDImager, automatic_depths, depth_span, volume_voxels
from nlosfw.plugins import load_plugins
from nlosfw.simulate import AnalyticSimulator, builtin_scene
from nlosfw.testing import fixtures
from nlosfw.transform import FFTTransform, PhasorField

RESULTS = RESULTS_DIR / "bench_speed.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'imagers', 'machine', 'quick', 'real_size', 'repeat', 'targets',
               'timing')
TARGETS = {"confocal_ratio": 2.0, "single_spot_ratio": 2.0, "real_size_seconds": 1.5}


def point_field(n: int, confocal: bool) -> PhasorField:
    """A point scatterer's field on an n x n wall of 2 m, 151 frequencies up to the limit."""
    spacing = 2.0 / n
    f_max = 1 / (2 * spacing * (2 if confocal else 1))
    freqs = np.linspace(f_max / 4, f_max, 151)
    return fixtures.point_field((0.1, -0.2, 1.0), shape=(n, n), spacing=spacing,
                                frequencies=freqs, confocal=confocal)


def plain_minimum(field: PhasorField, depths: np.ndarray, confocal: bool) -> np.ndarray:
    """A per-plane baseline written plainly: forward FFTs once, a depth-step propagator per
    plane; confocal sums frequencies with coefficients (``einsum``) before one inverse FFT
    per plane, single-spot needs one inverse FFT per frequency and plane (times a stand-in
    for the per-voxel laser phase). Not the minimal work: see ``bench_fft_minimum.py``."""
    n_f, ny, nx = field.values.shape
    shape = (scipy.fft.next_fast_len(2 * ny - 1), scipy.fft.next_fast_len(2 * nx - 1))
    dy, dx = field.grid_spacing() or (1.0, 1.0)
    m = 2 if confocal else 1
    spec = scipy.fft.fft2(field.values.astype(np.complex64), s=shape, workers=-1)
    ky = np.fft.fftfreq(shape[0], dy)[:, None]
    kx = np.fft.fftfreq(shape[1], dx)[None, :]
    kz = np.sqrt(((m * field.frequencies)[:, None, None] ** 2 - ky**2 - kx**2).astype(complex))
    current = spec * np.exp(2j * np.pi * kz * depths[0]).astype(np.complex64)
    step = np.exp(2j * np.pi * kz * (depths[1] - depths[0])).astype(np.complex64)
    coeffs = np.ones(n_f, dtype=np.complex64)
    out = np.empty((depths.size, ny, nx), dtype=np.float32)
    laser = None if confocal else np.exp(2j * np.pi * field.frequencies).astype(np.complex64)
    for i in range(depths.size):
        if laser is None:
            image = scipy.fft.ifft2(np.einsum("f,fyx->yx", coeffs, current), workers=-1)
            image = image[:ny, :nx]
        else:
            fields = scipy.fft.ifft2(current, workers=-1)[:, :ny, :nx]
            fields *= laser[:, None, None]                # stands in for the per-voxel phase
            image = np.einsum("f,fyx->yx", coeffs, fields)
        out[i] = np.abs(image) ** 2
        current *= step
    return out


def imager_case(n: int, planes: int, confocal: bool, repeat: int,
                shift: float = 0.0) -> dict[str, Any]:
    """The imager against the plain minimum on the wall's own grid, or (``shift``, in wall
    spacings) on voxel planes moved off it (no even kernel: the general path)."""
    field = point_field(n, confocal)
    spacing = 2.0 / n
    depths = np.linspace(0.6, 1.6, planes)
    voxels = volume_voxels(depths, (-1.0, 1.0), (-1.0, 1.0), (n, n))
    voxels[..., :2] += shift * spacing
    imager, one_thread = FFTImager(), FFTImager({"workers": 1})
    t_imager, recon = best_of(lambda: imager.reconstruct(field, voxels), repeat)
    t_one, _ = best_of(lambda: one_thread.reconstruct(field, voxels), repeat)
    t_plain, _ = best_of(lambda: plain_minimum(field, depths, confocal), repeat)
    return {"wall": [n, n], "spacing_m": spacing, "frequencies": 151, "planes": planes,
            "voxel_shift_spacings": shift,
            "padded": [scipy.fft.next_fast_len(2 * n - 1)] * 2,
            "imager_seconds": t_imager, "imager_one_thread_seconds": t_one,
            "plain_minimum_seconds": t_plain, "ratio": t_imager / t_plain,
            "ratio_one_thread": t_one / t_plain,
            "max_error_vs_direct_sum": direct_sum_error(field, voxels, recon.intensity)}


def direct_sum_error(field: PhasorField, voxels: np.ndarray, image: np.ndarray,
                     n: int = 256) -> float:
    """max |image - direct RSD sum| / max(image) at the brightest voxel and n - 1 random
    ones (the ``rsd`` imager evaluates the sum itself)."""
    flat = image.reshape(-1)
    rng = np.random.default_rng(0)
    picks = np.concatenate([[int(np.argmax(flat))], rng.choice(flat.size, n - 1, replace=False)])
    points = voxels.reshape(-1, 3)[picks]
    direct = RSDImager().reconstruct(field, points).intensity
    return float(np.max(np.abs(flat[picks] - direct)) / flat.max())


def real_size_case(repeat: int, quick: bool) -> dict[str, Any]:
    n = 32 if quick else 64
    scene = builtin_scene("letter_t", wall={"size": [0.7, 0.7], "resolution": [n, n]},
                          capture={"type": "confocal"},
                          time={"bins": 2048, "bin_width": 0.0012, "start": 0.2})
    start = time.perf_counter()
    capture = AnalyticSimulator().simulate(scene)
    simulate = time.perf_counter() - start
    transform = FFTTransform()
    t_transform, field = best_of(lambda: transform.transform(capture), repeat)
    depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                              field.geometry.kind)
    voxels = fixtures.aligned_voxels(field.wall_xyz, depths)
    host = load_plugins()
    rows: dict[str, Any] = {}
    for name in ("fft", "lct", "fk", "fbp"):
        imager = host.registry.create("imager", name)
        seconds, _ = best_of(lambda imager=imager: imager.reconstruct(field, voxels), repeat)
        rows[name] = seconds
    return {"capture": [2048, n, n], "simulate_seconds": simulate,
            "band": [float(field.frequencies[0]), float(field.frequencies[-1])],
            "frequencies": int(field.n_frequencies), "planes": int(depths.size),
            "depth_step_m": float(depths[1] - depths[0]),
            "transform_seconds": t_transform, "imager_seconds": rows,
            "fft_transform_plus_imaging_seconds": t_transform + rows["fft"]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    small = 32 if args.quick else 64
    cases = {
        f"confocal {small}x{small}, 96 planes": imager_case(small, 96, True, args.repeat),
        f"single_spot {small}x{small}, 96 planes": imager_case(small, 96, False, args.repeat),
        f"confocal {small}x{small}, 96 planes off the wall grid": imager_case(
            small, 96, True, args.repeat, shift=0.5),
    }
    if not args.quick:
        cases["confocal 128x128, 128 planes"] = imager_case(128, 128, True, args.repeat)
    results = {"benchmark": "bench_speed", "quick": args.quick, "repeat": args.repeat,
               "timing": "minimum of the repeats (shared cores)",
               "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                           "numpy": np.__version__},
               "imagers": cases, "real_size": real_size_case(args.repeat, args.quick),
               "targets": TARGETS}
    report(results)
    write_results(RESULTS, results, RESULT_KEYS)
    return results


def report(results: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"fft imager vs the per-plane baseline plain_minimum (min of "
                        f"{results['repeat']} runs, {results['machine']['cpus']} cores)")
    for col in ("case", "imager s", "plain_minimum s", "ratio", "target", "1 thread s",
                "ratio", "error"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for name, row in results["imagers"].items():
        table.add_row(name, f"{row['imager_seconds']:.3f}", f"{row['plain_minimum_seconds']:.3f}",
                      f"{row['ratio']:.2f}", "<= 2", f"{row['imager_one_thread_seconds']:.3f}",
                      f"{row['ratio_one_thread']:.2f}", f"{row['max_error_vs_direct_sum']:.1e}")
    real = results["real_size"]
    table.add_row(f"real size {real['capture']}: transform", f"{real['transform_seconds']:.3f}",
                  "", "", "")
    for name, seconds in real["imager_seconds"].items():
        table.add_row(f"  {name} imager ({real['planes']} planes)", f"{seconds:.3f}", "", "",
                      "")
    table.add_row("  transform + fft", f"{real['fft_transform_plus_imaging_seconds']:.3f}", "",
                  "", "<= 1.5 s")
    Console(width=120).print(table)


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

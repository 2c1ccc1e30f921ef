"""The ``fft`` imager against the minimal work of its reconstruction, timed side by side.

The minimal work of imaging a volume of depth planes from a wall field by FFT
convolution, written plainly (complex64, the FFTs on two workers), with what depends on
the geometry alone precomputed before the clock starts (the first plane's propagator
with the frequencies' coefficients, the depth step, the single-spot laser phases):

* one forward FFT of every frequency's zero-padded field;
* per plane, one in-place complex multiplication of the whole frequency x spectrum
  stack by the depth step, then
  - confocal: one sum over frequencies (the sum of a coherent image needs no per-voxel
    phase), and at the end one batched inverse FFT of all planes;
  - single spot: one inverse FFT per frequency (the laser leg's phase differs per voxel
    and frequency), one complex multiplication of the voxels' fields by that phase and
    one sum over frequencies;
* the intensity |.|^2.

The propagator is the angular spectrum's, exp(2 pi i kz z): the same amount of work as
the imager's operator, not the same operator (it is only timed here). The imager and the
minimum are timed in the same process, alternately, and each keeps the minimum of its
``--repeat`` runs (the machine's cores are shared). Fields: the confocal and single-spot
point scatterers of ``bench_speed.py`` (64 x 64, 151 frequencies, 96 planes, 128 x 128
padded) and the default scene (``thesis_two_planes``) captured confocally, transformed
and imaged at the automatic depths as a run does. ``plain_minimum`` (``bench_speed.py``:
a per-plane einsum with coefficients, a per-plane inverse FFT and abs()^2, several times
the minimal work) is timed beside them for reference. ``max_difference_vs_exact``: the
largest difference of the imager's image from its exact path's (``precision=double``),
relative to the exact image's maximum (the fast path's check). Beside the wall-clock
ratio: the imager on one thread (``workers=1``) over the minimal work, and the ratio of
CPU seconds (every thread's), the work done whatever the machine's load.

Results go to ``benchmarks/results/bench_fft_minimum.json``.

    python benchmarks/image/bench_fft_minimum.py [--quick] [--repeat N]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
import scipy.fft
from bench_speed import plain_minimum, point_field
from harness import RESULTS_DIR, machine, write_results
from rich.console import Console
from rich.table import Table

from nlosfw.image import FFTImager, automatic_depths, depth_span, volume_voxels
from nlosfw.simulate import AnalyticSimulator, builtin_scene
from nlosfw.testing import fixtures
from nlosfw.transform import FFTTransform, PhasorField

RESULTS = RESULTS_DIR / "bench_fft_minimum.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'cases', 'machine', 'quick', 'repeat', 'targets', 'timing')
TARGETS = {"confocal": 1.5, "single_spot": 2.0}
#: FFT threads of the minimal work.
FFT_WORKERS = 2


@dataclass(frozen=True)
class Minimum:
    """The precomputed inputs of the minimal work of one field and set of depth planes."""

    values: np.ndarray
    """The wall field (F, Y, X), complex64."""
    shape: tuple[int, int]
    first: np.ndarray
    """(F, Ly, Lx): propagator to the first plane times the frequencies' coefficients."""
    step: np.ndarray
    """(F, Ly, Lx): propagator over one depth step."""
    laser: np.ndarray | None
    """(F, Y, X): a per-voxel laser phase (single spot), None for confocal."""


def prepare_minimum(field: PhasorField, depths: np.ndarray) -> Minimum:
    """The geometry's share of the minimal work, computed before it is timed."""
    n_f, ny, nx = field.values.shape
    shape = (scipy.fft.next_fast_len(2 * ny - 1), scipy.fft.next_fast_len(2 * nx - 1))
    dy, dx = field.grid_spacing() or (1.0, 1.0)
    confocal = field.geometry.kind.value == "confocal"
    m = 2 if confocal else 1
    ky = np.fft.fftfreq(shape[0], dy)[:, None]
    kx = np.fft.fftfreq(shape[1], dx)[None, :]
    kz = np.sqrt(((m * field.frequencies)[:, None, None] ** 2 - ky**2 - kx**2).astype(complex))
    coeffs = field.effective_weights[:, None, None]
    first = (coeffs * np.exp(2j * np.pi * kz * depths[0])).astype(np.complex64)
    step = np.exp(2j * np.pi * kz * (depths[1] - depths[0])).astype(np.complex64)
    laser = None
    if not confocal:
        wall = field.wall_xyz
        r_l = np.linalg.norm(wall - np.asarray(field.geometry.laser_point), axis=-1)
        r_l = np.sqrt(r_l**2 + depths[0] ** 2)
        laser = np.exp(2j * np.pi * field.frequencies[:, None, None] * r_l).astype(np.complex64)
    return Minimum(field.values.astype(np.complex64), shape, first, step, laser)


def minimal_work(work: Minimum, planes: int) -> np.ndarray:
    """The images (planes, Y, X) by the minimal work (see the module docstring)."""
    n_f, ny, nx = work.values.shape
    spectra = scipy.fft.fft2(work.values, s=work.shape, workers=FFT_WORKERS)
    spectra *= work.first
    if work.laser is None:
        sums = np.empty((planes,) + work.shape, dtype=np.complex64)
        for i in range(planes):
            if i:
                spectra *= work.step
            spectra.sum(axis=0, out=sums[i])
        amplitude = scipy.fft.ifft2(sums, workers=FFT_WORKERS, overwrite_x=True)[:, :ny, :nx]
    else:
        amplitude = np.empty((planes, ny, nx), dtype=np.complex64)
        for i in range(planes):
            if i:
                spectra *= work.step
            fields = scipy.fft.ifft2(spectra, workers=FFT_WORKERS)[:, :ny, :nx]
            fields *= work.laser
            fields.sum(axis=0, out=amplitude[i])
    return amplitude.real**2 + amplitude.imag**2


def interleaved(calls: dict[str, Callable[[], object]], repeat: int
                ) -> tuple[dict[str, float], dict[str, float]]:
    """The minimum wall-clock and CPU seconds (every thread's) of each call over ``repeat``
    rounds, the calls alternating within each round (the same load on all of them)."""
    wall = dict.fromkeys(calls, float("inf"))
    cpu = dict.fromkeys(calls, float("inf"))
    for _ in range(max(1, repeat)):
        for name, call in calls.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            call()
            wall[name] = min(wall[name], time.perf_counter() - start)
            cpu[name] = min(cpu[name], time.process_time() - start_cpu)
    return wall, cpu


def measure(field: PhasorField, voxels: np.ndarray, depths: np.ndarray, repeat: int,
            plain: bool) -> dict[str, Any]:
    """The imager, the minimal work (and ``plain_minimum``) on one field, interleaved."""
    work = prepare_minimum(field, depths)
    imager, one_thread = FFTImager(), FFTImager({"workers": 1})
    confocal = field.geometry.kind.value == "confocal"
    calls: dict[str, Callable[[], object]] = {
        "imager": lambda: imager.reconstruct(field, voxels),
        "minimum": lambda: minimal_work(work, depths.size),
        "imager_one_thread": lambda: one_thread.reconstruct(field, voxels)}
    if plain:
        calls["plain_minimum"] = lambda: plain_minimum(field, depths, confocal)
    seconds, cpu = interleaved(calls, repeat)
    fast = imager.reconstruct(field, voxels).intensity
    exact = FFTImager({"precision": "double"}).reconstruct(field, voxels).intensity
    row: dict[str, Any] = {
        "wall": list(field.values.shape[1:]), "frequencies": int(field.n_frequencies),
        "planes": int(depths.size), "padded": list(work.shape),
        "imager_seconds": seconds["imager"], "minimum_seconds": seconds["minimum"],
        "ratio": seconds["imager"] / seconds["minimum"],
        "imager_one_thread_seconds": seconds["imager_one_thread"],
        "ratio_one_thread": seconds["imager_one_thread"] / seconds["minimum"],
        "cpu_seconds": cpu, "cpu_ratio": cpu["imager"] / cpu["minimum"],
        "max_difference_vs_exact": float(np.abs(fast - exact).max() / exact.max())}
    if plain:
        row["plain_minimum_seconds"] = seconds["plain_minimum"]
    return row


def point_case(n: int, confocal: bool, repeat: int) -> dict[str, Any]:
    depths = np.linspace(0.6, 1.6, 96)
    voxels = volume_voxels(depths, (-1.0, 1.0), (-1.0, 1.0), (n, n))
    return measure(point_field(n, confocal), voxels, depths, repeat, plain=True)


def scene_case(repeat: int, quick: bool) -> dict[str, Any]:
    """The default scene captured confocally, transformed and imaged as a run does."""
    n = 32 if quick else 64
    scene = builtin_scene("thesis_two_planes", wall={"resolution": [n, n]},
                          capture={"type": "confocal"})
    capture = AnalyticSimulator().simulate(scene)
    field = FFTTransform().transform(capture)
    depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                              field.geometry.kind)
    voxels = fixtures.aligned_voxels(field.wall_xyz, depths)
    return measure(field, voxels, depths, repeat, plain=False)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="32 x 32 walls (smoke run)")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    n = 32 if args.quick else 64
    cases = {
        f"confocal {n}x{n}, 96 planes": point_case(n, True, args.repeat),
        f"single_spot {n}x{n}, 96 planes": point_case(n, False, args.repeat),
        f"default scene, confocal {n}x{n}": scene_case(args.repeat, args.quick),
    }
    results = {"benchmark": "bench_fft_minimum", "quick": args.quick, "repeat": args.repeat,
               "timing": "minimum of the repeats, imager and minimal work alternating",
               "machine": machine(numpy=np.__version__, scipy=scipy.__version__),
               "cases": cases, "targets": TARGETS}
    report(results)
    if not args.quick:
        write_results(RESULTS, results, RESULT_KEYS)
    return results


def report(results: dict[str, Any]) -> None:
    table = Table(title=f"fft imager vs the minimal work (min of {results['repeat']} "
                        f"alternating runs, {results['machine']['cpus']} cores)")
    for col in ("case", "imager s", "minimum s", "ratio", "target", "1 thread", "CPU ratio",
                "plain_minimum s", "vs exact"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for name, row in results["cases"].items():
        target = TARGETS["confocal" if name.startswith(("confocal", "default")) else
                         "single_spot"]
        plain = row.get("plain_minimum_seconds")
        table.add_row(name, f"{row['imager_seconds']:.3f}", f"{row['minimum_seconds']:.3f}",
                      f"{row['ratio']:.2f}", f"<= {target}", f"{row['ratio_one_thread']:.2f}",
                      f"{row['cpu_ratio']:.2f}", "" if plain is None else f"{plain:.3f}",
                      f"{row['max_difference_vs_exact']:.1e}")
    Console(width=150).print(table)


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

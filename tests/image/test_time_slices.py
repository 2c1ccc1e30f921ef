"""The time slices of the ``fft`` imager's fast coherent confocal path.

The pieces against their definitions (the window's transform, the interpolation of every
frequency's phasor from the slices, the kernel's slices written block by block, the
slices' sum against the frequencies' sum), and the imager against the direct RSD sum
on closed-form point-scatterer fields: single precision (the slices) at 1e-4 of the
peak, double precision (every frequency's kernel, the exact path) at 1e-10.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import scipy.fft

from nlosfw import load_capture
from nlosfw.image import even_kernel, time_slices
from nlosfw.image.depths import automatic_depths, depth_span
from nlosfw.image.fft import FFTImager
from nlosfw.image.reconstruction import volume_voxels
from nlosfw.image.rsd import RSDImager
from nlosfw.image.time_slices import WIDTH, TimeSlices
from nlosfw.testing import fixtures
from nlosfw.transform.fft import FFTTransform
from tests.real_data import LCT_CAPTURES, real_capture


def test_window_spectrum_is_the_windows_fourier_transform():
    y = np.linspace(-WIDTH / 2, WIDTH / 2, 20001)
    xi = np.array([0.0, 0.1, 0.25, 0.4])
    phi = time_slices.window(y)
    expected = [np.trapezoid(phi * np.cos(2 * np.pi * x * y), y) for x in xi]
    np.testing.assert_allclose(time_slices.window_spectrum(xi), expected, rtol=1e-6)
    assert time_slices.window(np.array([WIDTH / 2, -WIDTH / 2 - 1]))[0] == 0
    assert time_slices.window(np.array([0.0]))[0] == 1


@pytest.mark.parametrize("n_f", [3, 40, 151])
def test_slices_interpolate_every_frequencys_phasor(n_f):
    """exp(2 pi i j' x) = sum_t phi(N x - t) exp(2 pi i j' t / N) / phi_hat(j' / N) for
    every j' of the frequencies, to 1e-6, at any x."""
    grid = time_slices.time_slices(np.linspace(2.0, 5.0, n_f), 2, 0.5, 1.5)
    assert grid is not None and grid.n >= 1.25 * n_f
    x = np.random.default_rng(0).uniform(-3.0, 7.0, 50)
    j = grid.offsets
    t = np.ceil(grid.n * x - WIDTH / 2)[:, None] + np.arange(WIDTH)[None, :]   # (x, W)
    taps = time_slices.window(grid.n * x[:, None] - t)
    sums = np.einsum("xw,xwj->xj", taps, np.exp(2j * np.pi * t[..., None] * j / grid.n))
    sums /= time_slices.window_spectrum(j / grid.n)
    np.testing.assert_allclose(sums, np.exp(2j * np.pi * np.outer(x, j)), rtol=0, atol=1e-6)


def test_time_slices_need_uniform_frequencies():
    assert time_slices.time_slices(np.array([2.0, 3.0]), 2, 0.5, 1.0) is None
    assert time_slices.time_slices(np.array([2.0, 3.0, 3.5]), 2, 0.5, 1.0) is None
    descending = time_slices.time_slices(np.linspace(5.0, 2.0, 31), 1, 0.5, 1.0)
    assert descending is not None and descending.step < 0


@pytest.mark.parametrize("size", [2, 7, 64])
@pytest.mark.parametrize("order", ["ascending", "descending"])
def test_kernel_blocks_hold_the_windowed_kernel(size, order):
    """Block by block (blocks of 2 and 7 split the plane's slices, 64 holds them all),
    written into a strided view and nowhere else: slice t holds
    g(u) phi(N x(u) - t), g the kernel at the middle frequency."""
    freqs = np.linspace(2.0, 5.0, 41)
    if order == "descending":
        freqs = freqs[::-1]
    r = np.random.default_rng(1).uniform(0.4, 0.7, (5, 4))
    grid = time_slices.time_slices(freqs, 2, 0.4, 0.7)
    assert grid is not None
    first, last = grid.span(float(r.min()), float(r.max()))
    x = grid.position(r)
    centre = freqs[grid.centre]
    buffer = np.full((size, 7, 6), np.nan + 0j, dtype=np.complex128)
    buffer[:, 1:6, 1:5] = 0
    seen = []
    for rows in grid.kernel_blocks(r, buffer[:, 1:6, 1:5]):
        slices = np.arange(first, last + 1)[len(seen):][:size]
        np.testing.assert_array_equal(np.atleast_1d(np.arange(grid.n)[rows]),
                                      (slices - grid.origin) % grid.n)
        for i, t in enumerate(slices):
            expected = np.exp(2j * np.pi * centre * 2 * r) / r * time_slices.window(x - t)
            np.testing.assert_allclose(buffer[i, 1:6, 1:5], expected, rtol=1e-12, atol=0)
        seen.extend(slices)
    assert seen == list(range(first, last + 1))
    assert np.isnan(buffer[:, 0]).all() and np.isnan(buffer[:, 6]).all()
    assert np.isnan(buffer[..., 0]).all() and np.isnan(buffer[..., 5]).all()


@pytest.mark.parametrize("n_f", [25, 80])
def test_slices_sum_is_the_frequencies_sum(n_f):
    """sum_t V_t(k) G_t(k) = sum_j S_j(k) H_j(k) (H_j the type-I DCT of the kernel's
    quarter at f_j, S_j random spectra) to 1e-6 of its largest value."""
    rng = np.random.default_rng(2)
    freqs = np.linspace(3.0, 6.0, n_f)
    n, step, z = 9, 0.05, 0.3
    u = step * np.arange(n)
    r = np.sqrt(u[:, None] ** 2 + u[None, :] ** 2 + z * z)
    spectra = rng.standard_normal((n_f, n + 1, n + 1)) + 1j * rng.standard_normal(
        (n_f, n + 1, n + 1))
    kernels = np.zeros((n_f, n + 1, n + 1), dtype=complex)
    kernels[:, :n, :n] = np.exp(2j * np.pi * freqs[:, None, None] * 2 * r) / r
    expected = np.sum(spectra * scipy.fft.dctn(kernels, type=1, axes=(1, 2)), axis=0)
    grid = time_slices.time_slices(freqs, 2, float(r.min()), float(r.max()))
    assert grid is not None
    rows = time_slices.time_spectra(grid, lambda sel: spectra[sel], axis=0, block=7)
    first, last = grid.span(float(r.min()), float(r.max()))
    work = np.zeros((last - first + 1, n + 1, n + 1), dtype=complex)
    got = np.zeros((n + 1, n + 1), dtype=complex)
    for sel in grid.kernel_blocks(r, work[:, :n, :n]):
        got += np.sum(rows[sel] * scipy.fft.dctn(work, type=1, axes=(1, 2)), axis=0)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(expected).max())


# ------------------------------------------------------------ the imager
def point_volume(shift: float = 0.0, n: int = 24, n_f: int = 61, legs: bool = False,
                 descending: bool = False):
    """A closed-form point scatterer's confocal field on an n x n wall of 1.2 m (frequencies
    up to the aliasing limit, Gaussian weights) and depth planes around it, on the wall's
    grid or moved ``shift`` wall spacings."""
    spacing = 1.2 / n
    f_max = 1 / (4 * spacing)
    freqs, weights = fixtures.gaussian_band(5 * f_max / 8, f_max / 8, n=n_f)
    if descending:
        freqs, weights = freqs[::-1], weights[::-1]
    field = fixtures.point_field((0.1, -0.15, 0.55), shape=(n, n), spacing=spacing,
                                 frequencies=freqs, weights=weights, confocal=True,
                                 device_legs=legs)
    voxels = volume_voxels(np.linspace(0.4, 0.7, 7), (-0.6, 0.6), (-0.6, 0.6), (n, n))
    voxels[..., :2] += shift * spacing
    return field, voxels


@pytest.fixture
def slice_blocks(monkeypatch):
    """The slices each plane's kernel blocks hold (so a test knows the fast path ran)."""
    counts: list[int] = []
    original = TimeSlices.kernel_blocks

    def counted(self, r, out):
        for rows in original(self, r, out):
            counts.append(int(np.arange(self.n)[rows].size))
            yield rows

    monkeypatch.setattr(TimeSlices, "kernel_blocks", counted)
    return counts


@pytest.mark.parametrize("case", ["aligned", "off the grid", "device legs", "descending",
                                  "virtual time", "small blocks"])
def test_fast_path_equals_the_direct_sum(case, slice_blocks, monkeypatch):
    """On the wall's grid (the even kernel) and off it, with the device legs in the field,
    descending frequencies, a virtual time, or blocks of 3 slices on 3 threads."""
    field, voxels = point_volume(shift=0.5 if case == "off the grid" else 0.0,
                                 legs=case == "device legs", descending=case == "descending")
    options = {"time": 0.05} if case == "virtual time" else {}
    if case == "small blocks":
        options = {"workers": 3}
        monkeypatch.setattr(FFTImager, "_rows_per_block", lambda self, volume, layout: 3)
    expected = RSDImager(options).reconstruct(field, voxels).intensity
    got = FFTImager(options).reconstruct(field, voxels).intensity
    assert np.max(np.abs(got - expected)) <= 1e-4 * expected.max()
    assert 0 < sum(slice_blocks) <= 0.75 * field.n_frequencies * voxels.shape[0]
    if case == "small blocks":
        assert max(slice_blocks) == 3
    exact = FFTImager({**options, "precision": "double"}).reconstruct(field, voxels)
    np.testing.assert_allclose(exact.intensity, expected, rtol=1e-10,
                               atol=1e-10 * expected.max())


def test_fast_path_transforms_fewer_kernels_than_frequencies(even_transforms):
    """The benchmark's shape at a small scale: a 32 x 32 wall of 2 m, 151 frequencies,
    24 planes from 0.6 m: under a third of the frequencies' transforms."""
    n = 32
    f_max = 1 / (2 * (2.0 / n) * 2)
    field = fixtures.point_field((0.1, -0.2, 1.0), shape=(n, n), spacing=2.0 / n,
                                 frequencies=np.linspace(f_max / 4, f_max, 151), confocal=True)
    voxels = volume_voxels(np.linspace(0.6, 1.6, 24), (-1.0, 1.0), (-1.0, 1.0), (n, n))
    FFTImager().reconstruct(field, voxels)
    assert 0 < sum(even_transforms) <= 151 * 24 / 3
    even_transforms.clear()
    FFTImager({"precision": "double"}).reconstruct(field, voxels)
    assert sum(even_transforms) == 151 * 24


@pytest.fixture
def even_transforms(monkeypatch):
    """Counts the kernels whose quarter is transformed."""
    calls: list[int] = []
    original = even_kernel.kernel_spectrum

    def counted(kernels, workers):
        calls.append(kernels.shape[0])
        return original(kernels, workers)

    monkeypatch.setattr(even_kernel, "kernel_spectrum", counted)
    return calls


def test_fast_path_only_where_it_applies(slice_blocks):
    """Several virtual times, incoherent images, few or irregular frequencies and a budget
    too small for the slices' spectra transform every frequency's kernel (and still give
    the direct sum)."""
    field, voxels = point_volume(n=12, n_f=41)
    irregular = field.replace(frequencies=field.frequencies * (1 + 0.002 * np.sin(
        np.arange(41))))
    few, few_voxels = point_volume(n=12, n_f=6)
    cases = [(FFTImager(), irregular, voxels), (FFTImager(), few, few_voxels),
             (FFTImager({"combine": "incoherent"}), field, voxels),
             (FFTImager({"chunk_mb": 0.05}), field, voxels)]
    for imager, f, v in cases:
        expected = RSDImager({"combine": imager.config.combine}).reconstruct(f, v).intensity
        got = imager.reconstruct(f, v).intensity
        assert np.max(np.abs(got - expected)) <= 2e-5 * expected.max()
    times = [0.0, 0.05]
    expected = RSDImager().reconstruct_time_resolved(field, voxels, times)
    got = FFTImager().reconstruct_time_resolved(field, voxels, times)
    assert np.max(np.abs(got - expected)) <= 2e-5 * expected.max()
    assert slice_blocks == []


@pytest.mark.parametrize("name", LCT_CAPTURES)
def test_fast_path_on_the_real_captures_is_the_exact_paths_image(name, slice_blocks):
    """The shared Stanford captures (binned 2 x 2), default transform, automatic depths:
    the fast path's volume correlates with the exact path's to 0.999 and more (measured:
    1 - 1e-12 at either size) and differs from it by at most 1e-4 of its peak (measured:
    1.6e-6)."""
    capture = load_capture(real_capture(name), bin=2)
    field = FFTTransform().transform(capture)
    depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                              field.geometry.kind)
    voxels = np.repeat(field.wall_xyz[None], depths.size, axis=0)
    voxels[..., 2] = depths[:, None, None]
    fast = FFTImager().reconstruct(field, voxels).intensity
    assert slice_blocks
    exact = FFTImager({"precision": "double"}).reconstruct(field, voxels).intensity
    assert np.corrcoef(fast.ravel(), exact.ravel())[0, 1] >= 0.999
    assert np.max(np.abs(fast - exact)) <= 1e-4 * exact.max()


@pytest.mark.parametrize("workers", [1, 2])
def test_fast_path_stays_within_its_memory_budget(workers, slice_blocks):
    """chunk_mb = 5 MiB holds the slices' spectra (2.2 MiB with a block of frequencies'
    while they are computed): the fast path runs, and the imaging's peak of allocated
    memory stays within the budget (measured: 2.7 MiB)."""
    field, voxels = point_volume()
    imager = FFTImager({"chunk_mb": 5.0, "workers": workers})
    imager.reconstruct(field, voxels)                        # imports, plans, caches
    tracemalloc.start()
    try:
        imager.reconstruct(field, voxels)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert slice_blocks
    assert peak <= 5 * 2**20, f"peak {peak / 2**20:.2f} MiB"

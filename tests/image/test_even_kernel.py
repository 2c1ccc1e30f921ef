"""The even-kernel plane convolution of the ``fft`` imager, which makes confocal
captures fast.

Its pieces against their definitions (mirror images and their inverse, the type-I DCT
against the full FFT of the circularly placed kernel, which layouts are even), and the
imager on even layouts against the direct RSD sum.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.fft

from nlosfw.image import even_kernel
from nlosfw.image.fft import FFTImager
from nlosfw.image.plane_convolution import PlaneConvolution, lattice_axis, read_points
from nlosfw.image.rsd import RSDImager
from nlosfw.testing import fixtures


def conv_of(n_wall: tuple[int, int], n_vox: tuple[int, int], offset=(0.0, 0.0),
            step=0.05) -> PlaneConvolution:
    axes = [lattice_axis(nw, step, nv, step, off) for nw, nv, off in zip(n_wall, n_vox, offset,
                                                                        strict=True)]
    assert axes[0] is not None and axes[1] is not None
    return PlaneConvolution(axes[0], axes[1], workers=1)


@pytest.mark.parametrize("shape", [(8, 8), (12, 6), (10, 14)])
def test_quarters_and_assemble_are_inverse(shape):
    rng = np.random.default_rng(1)
    full = rng.standard_normal((3,) + shape) + 1j * rng.standard_normal((3,) + shape)
    images = even_kernel.quarters(full)
    assert images.shape == (2, 2, 3, shape[0] // 2 + 1, shape[1] // 2 + 1)
    np.testing.assert_array_equal(even_kernel.assemble(images), full)
    ly, lx = shape
    # image (1, 0) at quarter index (p, q) holds full index (L_y - p, q); its rows 0 and
    # L_y / 2 belong to image (0, .) and are zero
    np.testing.assert_array_equal(images[1, 0, :, 2, 1], full[:, ly - 2, 1])
    np.testing.assert_array_equal(images[1, 1, :, 1, 2], full[:, ly - 1, lx - 2])
    assert not images[1, :, :, 0].any() and not images[1, :, :, ly // 2].any()
    assert not images[:, 1, :, :, 0].any() and not images[:, 1, :, :, lx // 2].any()


@pytest.mark.parametrize("n", [(6, 6), (7, 10), (32, 5)])
def test_quarter_spectrum_is_the_fft_of_the_circular_kernel(n):
    """The type-I DCT of the kernel's quarter is the unique quarter of the FFT of the whole
    kernel placed circularly (offset u at index u mod L), L even (32 wall points: 64, not
    the fast odd 63 of the general layout)."""
    conv = even_layout(n, n)
    assert even_kernel.is_even(conv)
    assert conv.shape == tuple(2 * scipy.fft.next_fast_len(k) for k in n)
    ly, lx = conv.shape
    r = even_kernel.distances(conv, 0.4)
    kern = np.exp(2j * np.pi * 9.0 * 2 * r) / r                          # u >= 0 per axis
    quarter = np.zeros((1,) + even_kernel.quarter_shape(conv), dtype=complex)
    quarter[(slice(None),) + even_kernel.kernel_region(conv)] = kern
    circular = np.zeros((ly, lx), dtype=complex)
    for uy in range(-(n[0] - 1), n[0]):
        for ux in range(-(n[1] - 1), n[1]):
            circular[uy % ly, ux % lx] = kern[abs(uy), abs(ux)]
    full = np.fft.fft2(circular)
    got = even_kernel.kernel_spectrum(quarter, workers=1)[0]
    np.testing.assert_allclose(got, full[:ly // 2 + 1, :lx // 2 + 1], rtol=0,
                               atol=1e-12 * np.abs(full).max())
    np.testing.assert_allclose(even_kernel.assemble(np.stack([np.stack([got] * 2)] * 2)), full,
                               rtol=0, atol=1e-12 * np.abs(full).max())


@pytest.mark.parametrize("shape", [(8, 8), (12, 6), (2, 4)])
def test_multiply_takes_the_even_spectrum_from_its_quarter(shape):
    """Full spectra times an even spectrum given by its quarter: the quarter's four mirror
    images assembled, times the spectra."""
    rng = np.random.default_rng(3)
    ly, lx = shape
    quarter = rng.standard_normal((3, ly // 2 + 1, lx // 2 + 1)) + 0j
    spectra = rng.standard_normal((3,) + shape) + 1j * rng.standard_normal((3,) + shape)
    even = np.array([[quarter[:, min(p, ly - p), min(q, lx - q)] for q in range(lx)]
                     for p in range(ly)]).transpose(2, 0, 1)
    out = np.full_like(spectra, np.nan)
    got = even_kernel.multiply(spectra, quarter, out=out)
    assert got is out
    np.testing.assert_array_equal(got, spectra * even)


@pytest.mark.parametrize("region", [(slice(0, 5), slice(0, 6)), (slice(3, 9, 2), slice(4, 10)),
                                    (slice(None), slice(None))])
def test_inverse_fft_read_at_some_points_is_the_full_inverse_fft_there(region):
    """The imagers' inverse FFTs read only the output rows after the first axis."""
    rng = np.random.default_rng(4)
    spectra = rng.standard_normal((3, 12, 10)) + 1j * rng.standard_normal((3, 12, 10))
    expected = np.fft.ifft2(spectra)[(slice(None),) + region]
    got = read_points(spectra.copy(), region, workers=1)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


def test_which_layouts_are_even():
    assert even_kernel.is_even(conv_of((7, 10), (7, 10)))             # L = 14 and 20
    assert not even_kernel.is_even(conv_of((6, 10), (6, 10)))          # L_y = 11 is odd
    assert even_kernel.is_even(even_layout((6, 10), (6, 10)))          # padded to 12 instead
    assert even_layout((7, 7), (8, 7)) is None                          # extents differ
    assert even_layout((7, 7), (7, 7), offset=(0.0, 0.01)) is None     # shifted grids
    assert even_layout((1, 7), (1, 7)) is None                          # one row
    assert even_kernel.is_even(even_layout((7, 7), (7, 7), offset=(1e-12, -1e-12)))


def even_layout(n_wall, n_vox, offset=(0.0, 0.0), step=0.05):
    conv = conv_of(n_wall, n_vox, offset, step)
    return even_kernel.even_layout(conv.ay, conv.ax, workers=1)


def _confocal_field(shape=(6, 10), n_f=40, seed=0):
    rng = np.random.default_rng(seed)
    base = fixtures.point_field((0.05, 0.02, 0.5), shape=shape, spacing=1 / 16,
                                frequencies=np.linspace(3.0, 5.0, n_f), confocal=True,
                                device_legs=True)
    values = rng.standard_normal(base.values.shape) + 1j * rng.standard_normal(base.values.shape)
    weights = rng.standard_normal(n_f) + 1j * rng.standard_normal(n_f)
    return base.replace(values=values, weights=weights)


@pytest.fixture
def even_calls(monkeypatch):
    """Counts the even path's kernel transforms (so a test knows the path ran)."""
    calls = []
    original = even_kernel.kernel_spectrum

    def counted(kernels, workers):
        calls.append(kernels.shape[0])
        return original(kernels, workers)

    monkeypatch.setattr(even_kernel, "kernel_spectrum", counted)
    return calls


@pytest.mark.parametrize("options", [{}, {"workers": 1}, {"chunk_mb": 0.01},
                                     {"chunk_mb": 0.01, "workers": 3}])
def test_even_fold_equals_the_direct_sum(options, even_calls):
    """The wall's own grid at three depths (the usual volume), 40 frequencies in several
    blocks, the spectrum cached or computed per block, on 1-3 threads."""
    field = _confocal_field()
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.3, 0.45, 0.6])
    expected = RSDImager().reconstruct(field, voxels).intensity
    got = FFTImager({**options, "precision": "double"}).reconstruct(field, voxels).intensity
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-11 * expected.max())
    assert sum(even_calls) == 3 * 40
    single = FFTImager({**options, "precision": "single"}).reconstruct(field, voxels)
    assert np.max(np.abs(single.intensity - expected)) <= 2e-5 * expected.max()


def test_even_fold_at_several_virtual_times_and_finer_voxels(even_calls):
    """Two virtual times (the coefficients are summed per time, not folded into the
    spectrum), and voxels twice as fine as the wall over the same extent."""
    field = _confocal_field(shape=(6, 9), n_f=24, seed=2)
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.35, 0.5])
    times = [0.0, 0.08]
    expected = RSDImager().reconstruct_time_resolved(field, voxels, times)
    got = FFTImager({"precision": "double"}).reconstruct_time_resolved(field, voxels, times)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-11 * expected.max())
    assert sum(even_calls) == 2 * 24
    wall = field.wall_xyz                                       # (Y, X, 3), x along axis 1
    ys = np.linspace(wall[0, 0, 1], wall[-1, 0, 1], 2 * wall.shape[0] - 1)
    xs = np.linspace(wall[0, 0, 0], wall[0, -1, 0], 2 * wall.shape[1] - 1)
    fine = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], 0.4), axis=-1)
    expected = RSDImager().reconstruct(field, fine).intensity
    got = FFTImager({"precision": "double"}).reconstruct(field, fine).intensity
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-11 * expected.max())
    assert sum(even_calls) > 2 * 24

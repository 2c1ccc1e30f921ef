"""The built-in imagers ``rsd`` and ``fft``.

Generic physics (focusing, reference agreement, translation) is in the
conformance checks; here: the whole chain from the analytic simulator, device
legs, tight rsd/fft/reference agreement, finer and coarser voxel spacings, arbitrary
voxel sets, chunking, time-resolved images and bad input.
"""

from __future__ import annotations

import threading
import tracemalloc

import numpy as np
import pytest

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common import cores
from nlosfw.common.errors import DataError
from nlosfw.image.fft import FFTImager
from nlosfw.image.reconstruction import Reconstruction, volume_voxels
from nlosfw.image.rsd import RSDImager
from nlosfw.image.rsd_kernel import kernel_blocks, phasor_blocks, phasor_series, phasor_steps
from nlosfw.testing import fixtures, reference
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import PhasorField
from nlosfw.transform.wavelet import WaveletTransform

SPACING = 1 / 16


def random_field(shape=(6, 9), n_f=5, confocal=False, legs=False, seed=0) -> PhasorField:
    """A random complex field (every kernel detail matters, nothing is symmetric)."""
    rng = np.random.default_rng(seed)
    base = fixtures.point_field((0.05, 0.02, 0.5), shape=shape, spacing=SPACING,
                                frequencies=np.linspace(3.0, 5.0, n_f), confocal=confocal,
                                device_legs=legs)
    values = rng.standard_normal(base.values.shape) + 1j * rng.standard_normal(base.values.shape)
    weights = rng.standard_normal(n_f) + 1j * rng.standard_normal(n_f)
    return base.replace(values=values, weights=weights)


def peak_voxel(recon: Reconstruction) -> np.ndarray:
    idx = np.unravel_index(np.argmax(recon.intensity), recon.intensity.shape)
    return recon.voxels[idx]


# ------------------------------------------------------------ the whole chain
@pytest.mark.parametrize("confocal", [False, True])
def test_analytic_point_through_wavelet_is_focused_by_both_imagers(confocal):
    target = (0.125, -0.075, 0.55)                                     # a voxel centre
    capture = fixtures.point_capture(target=target, resolution=(24, 16), size=(1.2, 0.8),
                                     confocal=confocal, bins=600, bin_width=0.005)
    field = WaveletTransform().transform(capture)                      # lambda_c = 0.2 m
    wall = field.wall_xyz                                              # (16, 24, 3), 5 cm
    voxels = fixtures.aligned_voxels(wall, np.arange(0.35, 0.76, 0.05))
    for imager in (RSDImager(), FFTImager()):
        peak = peak_voxel(imager.reconstruct(field, voxels))
        assert np.all(np.abs(peak - target) <= [0.05 + 1e-9, 0.05 + 1e-9, 0.05 + 1e-9]), (
            type(imager).__name__, peak)


def test_analytic_point_through_fft_transform_single_frequency():
    target = (-0.1, 0.05, 0.5)
    capture = fixtures.point_capture(target=target, resolution=(24, 16), size=(1.2, 0.8))
    field = FFTTransform({"frequencies": [5.0]}).transform(capture)
    plane = fixtures.aligned_voxels(field.wall_xyz, [0.5])[0]
    for imager in (RSDImager(), FFTImager()):
        peak = peak_voxel(imager.reconstruct(field, plane))
        np.testing.assert_allclose(peak[:2], target[:2], atol=0.05 + 1e-9)


@pytest.mark.parametrize("confocal", [False, True])
def test_device_legs_removed_or_kept_focus_to_the_same_voxel(confocal):
    target = (0.1, 0.05, 0.5)
    capture = fixtures.point_capture(target=target, resolution=(16, 12), size=(0.8, 0.6),
                                     confocal=confocal, device_legs=True, bins=500,
                                     bin_width=0.01)
    removed = WaveletTransform().transform(capture)
    kept = WaveletTransform({"remove_device_legs": False}).transform(capture)
    assert kept.geometry.t_accounts_first_and_last_bounces
    voxels = fixtures.aligned_voxels(removed.wall_xyz, np.arange(0.3, 0.71, 0.05))
    for imager in (RSDImager(), FFTImager({"precision": "double"})):
        a = imager.reconstruct(removed, voxels)
        b = imager.reconstruct(kept, voxels)
        np.testing.assert_allclose(peak_voxel(a), peak_voxel(b))
        assert np.all(np.abs(peak_voxel(a) - target) <= 0.05 + 1e-9)
        np.testing.assert_allclose(a.intensity, b.intensity, rtol=0,
                                   atol=1e-9 * a.intensity.max())


# ------------------------------------------------------------ agreement
@pytest.mark.parametrize("confocal, legs", [(False, False), (False, True), (True, True)])
def test_rsd_equals_the_plain_reference(confocal, legs):
    field = random_field(confocal=confocal, legs=legs)
    voxels = np.random.default_rng(1).uniform([-0.4, -0.3, 0.2], [0.4, 0.3, 0.9], (25, 3))
    for time in (0.0, 0.13):
        got = RSDImager({"time": time}).reconstruct(field, voxels).intensity
        expected = reference.naive_rsd(field, voxels, time=time)
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12 * expected.max())


def test_rsd_uniform_and_irregular_frequencies_use_the_same_kernel():
    field = random_field(n_f=40)                       # uniform: the recurrence (refreshed)
    irregular = field.replace(frequencies=field.frequencies * (1 + 0.01 * np.sin(
        np.arange(40))))
    voxels = volume_voxels([0.4, 0.7], (-0.3, 0.3), (-0.2, 0.2), (3, 4))
    for f in (field, irregular):
        got = RSDImager().reconstruct(f, voxels).intensity
        expected = reference.naive_rsd(f, voxels)
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * expected.max())


@pytest.mark.parametrize("confocal", [False, True])
@pytest.mark.parametrize("precision, tol", [("single", 2e-5), ("double", 1e-11)])
def test_fft_equals_rsd_on_unaligned_planes(confocal, precision, tol):
    field = random_field(shape=(7, 10), confocal=confocal, legs=True)
    # voxel planes larger than the wall, shifted by a fraction of a sample
    voxels = _with_spacing(volume_voxels([0.3, 0.55], (0, 1), (0, 1), (11, 16)), SPACING,
                           SPACING, origin=(-0.31, -0.4))         # 1.9 samples off the wall
    fast = FFTImager({"precision": precision}).reconstruct(field, voxels).intensity
    slow = RSDImager().reconstruct(field, voxels).intensity
    assert np.max(np.abs(fast - slow)) <= tol * slow.max()


@pytest.mark.parametrize("ky, kx", [(2, 2), (1, 3), (4, 2)])
def test_fft_finer_voxel_spacing_equals_rsd(ky, kx):
    field = random_field(shape=(6, 8), legs=True)
    voxels = _with_spacing(volume_voxels([0.45], (0, 1), (0, 1), (13, 17)), SPACING / ky,
                           SPACING / kx, origin=(-0.21, -0.17))
    fast = FFTImager({"precision": "double"}).reconstruct(field, voxels).intensity
    slow = RSDImager().reconstruct(field, voxels).intensity
    assert np.max(np.abs(fast - slow)) <= 1e-10 * slow.max()


@pytest.mark.parametrize("ky, kx", [(2, 2), (1, 3)])
@pytest.mark.parametrize("confocal", [False, True])
def test_fft_coarser_voxel_spacing_equals_rsd(ky, kx, confocal):
    """Voxels k times coarser than the wall (the shared lattice reads every k-th point)."""
    field = random_field(shape=(9, 10), confocal=confocal, legs=True)
    voxels = _with_spacing(volume_voxels([0.45, 0.6], (0, 1), (0, 1), (5, 4)), SPACING * ky,
                           SPACING * kx, origin=(-0.21, -0.17))
    fast = FFTImager({"precision": "double"}).reconstruct(field, voxels).intensity
    slow = RSDImager().reconstruct(field, voxels).intensity
    assert np.max(np.abs(fast - slow)) <= 1e-10 * slow.max()


def test_fft_accepts_flipped_and_transposed_grids():
    field = random_field(shape=(6, 8))
    plane = _with_spacing(volume_voxels([0.5], (0, 1), (0, 1), (9, 7)), SPACING, SPACING)[0]
    expected = RSDImager().reconstruct(field, plane).intensity
    fft = FFTImager({"precision": "double"})
    for view in (plane[::-1], plane[:, ::-1], plane.transpose(1, 0, 2),
                 plane[::-1, ::-1].transpose(1, 0, 2)):
        want = RSDImager().reconstruct(field, view).intensity
        np.testing.assert_allclose(fft.reconstruct(field, view).intensity, want, rtol=1e-9,
                                   atol=1e-12 * expected.max())
    flipped = field.replace(values=field.values[:, ::-1, ::-1], wall_xyz=field.wall_xyz[::-1, ::-1])
    np.testing.assert_allclose(fft.reconstruct(flipped, plane).intensity, expected, rtol=1e-9,
                               atol=1e-12 * expected.max())


def test_confocal_frequency_folding_matches_per_frequency_imaging():
    """The confocal coherent shortcut (sum before one inverse FFT) changes nothing."""
    field = random_field(shape=(6, 8), confocal=True)
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.4, 0.6])
    coherent = FFTImager({"precision": "double"}).reconstruct(field, voxels).intensity
    expected = RSDImager().reconstruct(field, voxels).intensity
    np.testing.assert_allclose(coherent, expected, rtol=1e-9, atol=1e-12 * expected.max())


# ------------------------------------------------------------ options
def test_incoherent_sum_is_the_sum_of_single_frequency_images():
    field = random_field()
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.5])
    for imager in (RSDImager, FFTImager):
        total = imager({"combine": "incoherent", "precision": "double"} if imager is FFTImager
                       else {"combine": "incoherent"}).reconstruct(field, voxels).intensity
        parts = sum(RSDImager().reconstruct(field.select(i), voxels).intensity
                    for i in range(field.n_frequencies))
        np.testing.assert_allclose(total, parts, rtol=1e-9)


def test_time_resolved_images_peak_when_the_pulse_focuses():
    f, w = fixtures.gaussian_band(4.0, 0.75, n=15)
    target = (0.125, -0.0625, 0.5)
    field = fixtures.point_field(target, frequencies=f, weights=w)
    at_target = np.array([[target]])                                   # (1, 1, 3)
    nearer = at_target - [0, 0, 0.05]
    times = np.linspace(-0.3, 0.3, 121)
    for imager in (RSDImager(), FFTImager({"precision": "double"})):
        series = imager.reconstruct_time_resolved(field, at_target, times)[:, 0, 0]
        assert abs(times[np.argmax(series)]) <= 0.005
        later = imager.reconstruct_time_resolved(field, nearer, times)[:, 0, 0]
        # a voxel 5 cm nearer the wall sees the pulse ~2 x 5 cm of path later
        assert 0.05 <= times[np.argmax(later)] <= 0.11
    plane = fixtures.aligned_voxels(field.wall_xyz, [0.5])[0]
    np.testing.assert_allclose(
        RSDImager().reconstruct_time_resolved(field, plane, [0.0, 0.1]),
        FFTImager({"precision": "double"}).reconstruct_time_resolved(field, plane, [0.0, 0.1]),
        rtol=1e-9, atol=1e-12)
    shifted = RSDImager({"time": 0.1}).reconstruct(field, plane).intensity
    np.testing.assert_allclose(
        shifted, RSDImager().reconstruct_time_resolved(field, plane, [0.1])[0], rtol=1e-12)


def test_rsd_accepts_points_planes_and_volumes_alike():
    field = random_field()
    volume = volume_voxels([0.4, 0.6], (-0.3, 0.3), (-0.2, 0.2), (4, 5))
    rsd = RSDImager()
    as_volume = rsd.reconstruct(field, volume).intensity
    as_points = rsd.reconstruct(field, volume.reshape(-1, 3)).intensity
    as_plane = rsd.reconstruct(field, volume[1]).intensity
    np.testing.assert_allclose(as_points.reshape(as_volume.shape), as_volume, rtol=1e-12)
    np.testing.assert_allclose(as_plane, as_volume[1], rtol=1e-12)


def test_rsd_on_a_non_planar_wall():
    field = random_field()
    wall = field.wall_xyz.copy()
    wall[..., 2] = 0.02 * np.sin(7 * wall[..., 0])                   # a bumpy relay wall
    bumpy = field.replace(wall_xyz=wall)
    voxels = volume_voxels([0.5], (-0.2, 0.2), (-0.2, 0.2), (3, 3))
    np.testing.assert_allclose(RSDImager().reconstruct(bumpy, voxels).intensity,
                               reference.naive_rsd(bumpy, voxels), rtol=1e-10)
    with pytest.raises(DataError, match="regular"):
        FFTImager().reconstruct(bumpy, voxels)


@pytest.mark.parametrize("order", ["ascending", "descending", "shuffled", "irregular"])
def test_phasor_steps_are_the_closed_form_phasors(order):
    """Each phasor of the recurrence (600 steps: two exact refreshes) is exp(2 pi i f d) / d."""
    rng = np.random.default_rng(3)
    path = rng.uniform(0.2, 3.0, (7, 5))
    scale = 1.0 / path
    freqs = 2.0 + 0.05 * np.arange(600)
    if order == "descending":
        freqs = freqs[::-1]
    elif order == "shuffled":
        freqs = rng.permutation(freqs)
    elif order == "irregular":
        freqs = freqs * (1 + 0.01 * np.sin(np.arange(600)))
    expected = np.exp(2j * np.pi * freqs[:, None, None] * path) * scale
    seen = np.zeros(freqs.size, dtype=int)
    for i, phasor in phasor_steps(freqs, path, scale=scale):
        np.testing.assert_allclose(phasor, expected[i], rtol=1e-12, atol=0)
        seen[i] += 1
    assert np.all(seen == 1)
    np.testing.assert_allclose(phasor_series(freqs, path, scale=scale), expected, rtol=1e-12,
                               atol=0)
    single = phasor_series(freqs, path, np.complex64, scale=scale)
    assert single.dtype == np.complex64
    np.testing.assert_allclose(single, expected, rtol=2e-6, atol=0)


def test_phasor_steps_memory_does_not_grow_with_frequencies():
    path = np.random.default_rng(4).uniform(0.2, 3.0, (128, 128))    # 256 KiB of complex128
    tracemalloc.start()
    try:
        for _ in phasor_steps(np.linspace(1.0, 9.0, 2000), path, scale=1.0 / path):
            pass
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # a handful of (128, 128) arrays, not 2000 of them (500 MiB)
    assert peak < 12 * path.nbytes, f"peak {peak / 2**20:.1f} MiB"


def test_chunking_changes_nothing_and_bounds_memory():
    field = random_field(shape=(16, 16), n_f=8)
    voxels = volume_voxels(np.linspace(0.3, 0.9, 8), (-0.5, 0.5), (-0.5, 0.5), (32, 32))
    small = RSDImager({"chunk_mb": 0.05}).reconstruct(field, voxels).intensity
    large = RSDImager({"chunk_mb": 64}).reconstruct(field, voxels).intensity
    np.testing.assert_allclose(small, large, rtol=1e-12)
    fft_small = FFTImager({"chunk_mb": 0.05, "precision": "double"})
    np.testing.assert_allclose(fft_small.reconstruct(field, voxels).intensity, large,
                               rtol=1e-9, atol=1e-12 * large.max())
    tracemalloc.start()
    try:
        RSDImager({"chunk_mb": 1, "workers": 2}).reconstruct(field, voxels)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # voxels (0.2 MiB) + output + a few blocks of 1 MiB per worker (2 workers, whatever the
    # machine's cores), not voxels x samples x 16 B (32 MiB)
    assert peak < 6 * 2**20, f"peak {peak / 2**20:.1f} MiB"


@pytest.mark.parametrize("dtype, rtol", [(np.complex128, 1e-12), (np.complex64, 2e-6)])
@pytest.mark.parametrize("order", ["ascending", "descending", "irregular"])
@pytest.mark.parametrize("size", [2, 7])
def test_kernel_blocks_are_the_closed_form_kernels(size, order, dtype, rtol):
    """Every block of the 600 frequencies holds exp(2 pi i f m r) / r (blocks of 2 pass the
    exact refresh at block 256, blocks of 7 end with a partial block), written into a
    strided view and nowhere else."""
    rng = np.random.default_rng(5)
    r = rng.uniform(0.2, 3.0, (7, 5))
    freqs = 2.0 + 0.05 * np.arange(600)
    if order == "descending":
        freqs = freqs[::-1]
    elif order == "irregular":
        freqs = freqs * (1 + 0.01 * np.sin(np.arange(600)))
    expected = np.exp(2j * np.pi * freqs[:, None, None] * 2 * r) / r
    buffer = np.zeros((size, 9, 8), dtype=dtype)
    seen: list[int] = []
    for sel in kernel_blocks(freqs, r, 2, buffer[:, 1:8, 2:7]):
        block = buffer[:sel.stop - sel.start, 1:8, 2:7]
        np.testing.assert_allclose(block, expected[sel], rtol=rtol, atol=0)
        seen.extend(range(sel.start, sel.stop))
    assert sorted(seen) == list(range(600))
    assert not buffer[:, 0].any() and not buffer[:, 8].any() and not buffer[..., :2].any()
    assert not buffer[..., 7].any()
    unscaled = np.empty((size,) + r.shape, dtype=dtype)                    # no 1 / r
    for sel in phasor_blocks(freqs, r, unscaled):
        np.testing.assert_allclose(unscaled[:sel.stop - sel.start],
                                   np.exp(2j * np.pi * freqs[sel, None, None] * r), rtol=rtol,
                                   atol=0)


@pytest.mark.parametrize("kind", ["confocal", "confocal_two_times", "single_spot",
                                  "incoherent"])
def test_fft_blocks_threads_and_uncached_spectra_equal_rsd(kind):
    """40 frequencies make blocks of 16, 16 and 8; 1, 2 or 3 threads over the planes, and a
    spectrum computed per block of one frequency instead of cached, all give the direct
    sum (and the thread count changes no bit)."""
    field = random_field(shape=(6, 8), n_f=40, confocal=kind.startswith("confocal"),
                         legs=True)
    voxels = _with_spacing(volume_voxels([0.3, 0.45, 0.6], (0, 1), (0, 1), (7, 9)), SPACING,
                           SPACING)
    options = {"combine": "incoherent"} if kind == "incoherent" else {}

    def image(imager):
        if kind == "confocal_two_times":
            return imager.reconstruct_time_resolved(field, voxels, [0.0, 0.1])
        return imager.reconstruct(field, voxels).intensity

    expected = image(RSDImager(options))
    by_threads = []
    for extra in ({"workers": 1}, {"workers": 2}, {"workers": 3},
                  {"workers": 2, "chunk_mb": 0.01}):
        got = image(FFTImager({**options, **extra, "precision": "double"}))
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-11 * expected.max())
        by_threads.append(got)
    assert np.array_equal(by_threads[0], by_threads[1])
    assert np.array_equal(by_threads[0], by_threads[2])


@pytest.mark.parametrize("imager", [FFTImager({"workers": 2}),
                                    RSDImager({"workers": 2, "chunk_mb": 0.01})])
def test_imagers_start_no_more_blocks_after_an_error(imager, monkeypatch):
    """An error in one thread (here the progress callback) stops the imaging: the planes
    (voxel blocks) not yet started are cancelled, not computed before the error is raised.

    A block a thread takes up after the error is held until the thread pool shuts down
    (the error has reached the caller, which cancelled what had not started), however
    slowly the caller is scheduled: two blocks before the error, at most one more per
    thread after it. Without the cancelling the threads would go on to all 40."""
    failed, stopping = threading.Event(), threading.Event()

    class Watched(cores.ThreadPoolExecutor):
        def submit(self, fn, /, *args, **kwargs):
            def held(*a, **k):
                if failed.is_set():
                    assert stopping.wait(600), "the thread pool did not shut down in 600 s"
                return fn(*a, **k)

            return super().submit(held, *args, **kwargs)

        def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
            stopping.set()
            super().shutdown(wait, cancel_futures=cancel_futures)

    monkeypatch.setattr(cores, "ThreadPoolExecutor", Watched)
    field = random_field(shape=(6, 8))
    voxels = fixtures.aligned_voxels(field.wall_xyz, np.linspace(0.3, 0.9, 40))
    calls: list[int] = []

    def on_progress(done: int, total: int) -> None:
        calls.append(done)
        if done == 1:
            failed.set()
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        imager.reconstruct(field, voxels, on_progress=on_progress)
    assert stopping.is_set() and 1 <= len(calls) <= 4 and calls[0] == 1


def test_metadata_names_the_imager_and_frequencies():
    field = random_field()
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.5])
    for imager, name in ((RSDImager(), "rsd"), (FFTImager(), "fft")):
        meta = imager.reconstruct(field, voxels).metadata
        assert meta["imager"] == name
        assert meta["frequencies"] == pytest.approx(field.frequencies.tolist())
        assert meta["weighted"] is True and meta["combine"] == "coherent"


# ------------------------------------------------------------ bad input
def test_fft_refuses_voxels_it_cannot_convolve():
    field = random_field()
    fft = FFTImager()
    plane = fixtures.aligned_voxels(field.wall_xyz, [0.5])[0]
    with pytest.raises(DataError, match="point list"):
        fft.reconstruct(field, plane.reshape(-1, 3))
    tilted = plane.copy()
    tilted[..., 2] += 0.1 * tilted[..., 0]
    with pytest.raises(DataError, match="not parallel"):
        fft.reconstruct(field, tilted)
    irregular = plane.copy()
    irregular[:, 3, 0] += 0.01
    with pytest.raises(DataError, match="regular"):
        fft.reconstruct(field, irregular)
    coarse = _with_spacing(volume_voxels([0.5], (0, 1), (0, 1), (4, 4)), SPACING / 0.7, SPACING)
    with pytest.raises(DataError, match="whole number"):
        fft.reconstruct(field, coarse)
    with pytest.raises(DataError) as info:
        fft.reconstruct(field, plane.reshape(-1, 3))
    assert "\n" not in str(info.value) and "rsd imager" in str(info.value)


def test_fft_refuses_a_volume_with_one_bad_plane():
    """A volume's planes share the first one's grid check, each has its own flatness
    check: the error names the plane at fault, as plane by plane."""
    field = random_field()
    volume = fixtures.aligned_voxels(field.wall_xyz, [0.4, 0.5, 0.6])
    tilted = volume.copy()
    tilted[2, ..., 2] += 0.1 * tilted[2, ..., 0]
    with pytest.raises(DataError, match="plane 2 is not parallel"):
        FFTImager().reconstruct(field, tilted)
    irregular = volume.copy()
    irregular[1, 3, 0, 0] += 0.01                     # plane 1 has its own (bad) grid
    with pytest.raises(DataError, match="plane 1 is not a regular"):
        FFTImager().reconstruct(field, irregular)


@pytest.mark.parametrize("imager", [RSDImager(), FFTImager()])
def test_bad_fields_and_voxels(imager):
    field = random_field()
    plane = fixtures.aligned_voxels(field.wall_xyz, [0.5])[0]
    exhaustive = field.replace(geometry=CaptureGeometry(kind=CaptureKind.EXHAUSTIVE))
    no_spot = field.replace(geometry=CaptureGeometry(kind=CaptureKind.SINGLE_SPOT))
    for bad in (exhaustive, no_spot):
        with pytest.raises(DataError, match="field.geometry"):
            imager.reconstruct(bad, plane)
    with pytest.raises(DataError, match="PhasorField"):
        imager.reconstruct(field.values, plane)
    with pytest.raises(DataError, match="voxels"):
        imager.reconstruct(field, plane[..., :2])
    nan = plane.copy()
    nan[0, 0, 0] = np.nan
    with pytest.raises(DataError, match="NaN"):
        imager.reconstruct(field, nan)
    with pytest.raises(DataError, match="z must be > 0"):
        imager.reconstruct(field, plane * [1, 1, -1])


def _with_spacing(voxels: np.ndarray, dy: float, dx: float,
                  origin: tuple[float, float] = (-0.31, -0.4)) -> np.ndarray:
    """Replace the (x, y) of planes (Z, Y, X, 3) by a grid of steps (dy, dx) from ``origin``."""
    out = np.array(voxels, dtype=float)
    ny, nx = out.shape[-3:-1]
    out[..., 0] = origin[1] + dx * np.arange(nx)[None, :]
    out[..., 1] = origin[0] + dy * np.arange(ny)[:, None]
    return out


# ------------------------------------------------------------ summaries
def test_depth_map_and_max_image_of_an_imaged_point():
    f, w = fixtures.gaussian_band(4.0, 0.75, n=11)
    target = (0.15625, -0.09375, 0.57)                    # between the planes 0.55 and 0.60
    field = fixtures.point_field(target, frequencies=f, weights=w)
    voxels = fixtures.aligned_voxels(field.wall_xyz, np.arange(0.40, 0.76, 0.05))
    recon = FFTImager().reconstruct(field, voxels)
    depth, image = recon.depth_and_max_images(threshold=0.5)
    iy, ix = np.unravel_index(np.argmax(image), image.shape)
    np.testing.assert_allclose(field.wall_xyz[iy, ix, :2], target[:2])
    np.testing.assert_allclose(image, recon.intensity.max(axis=0))
    assert abs(depth[iy, ix] - target[2]) <= 0.05
    assert np.isnan(depth).sum() > 0.5 * depth.size       # dim pixels are "nothing there"


def test_refined_depth_map_finds_the_vertex_between_planes():
    z = np.array([0.4, 0.5, 0.6, 0.7, 0.8])
    z0 = np.array([[0.53, 0.66], [0.8, 0.4]])             # two inside, two at the ends
    intensity = 10 - (z[:, None, None] - z0[None]) ** 2   # exact parabolas along depth
    voxels = np.zeros(intensity.shape + (3,))
    voxels[..., 2] = z[:, None, None]
    recon = Reconstruction(intensity=intensity, voxels=voxels)
    np.testing.assert_allclose(recon.depth_map(), [[0.5, 0.7], [0.8, 0.4]])
    np.testing.assert_allclose(recon.depth_map(refine=True), z0, atol=1e-12)

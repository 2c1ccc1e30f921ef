"""The scores of a run's reconstructions, on cases worked out by hand: amplitudes
normalised to their maximum, front view and volume, and the depth RMSE against a truth map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nlosfw.common.errors import DataError
from nlosfw.evaluation.image_scores import depth_rmse, reconstruction_scores, resample_nearest
from nlosfw.image.reconstruction import Reconstruction, volume_voxels

DEPTHS = np.array([0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2])


def _recon(intensity: np.ndarray) -> Reconstruction:
    nz, ny, nx = intensity.shape
    voxels = volume_voxels(DEPTHS[:nz], (-0.5, 0.5), (-0.5, 0.5), (ny, nx))
    return Reconstruction(intensity=intensity, voxels=voxels)


def _peaks(planes: np.ndarray, ny: int = 10, nx: int = 12) -> Reconstruction:
    """A volume whose column (y, x) is brightest in plane planes[y, x] (intensity 4 there,
    1 elsewhere)."""
    intensity = np.ones((DEPTHS.size, ny, nx))
    for (y, x), k in np.ndenumerate(planes):
        intensity[k, y, x] = 4.0
    return _recon(intensity)


def test_identical_reconstructions_score_inf_and_one():
    rng = np.random.default_rng(0)
    recon = _recon(rng.random((8, 10, 12)))
    scores = reconstruction_scores(recon, recon)
    assert scores["psnr"] == math.inf and scores["volume_psnr"] == math.inf
    assert scores["ssim"] == pytest.approx(1.0) and scores["volume_ssim"] == pytest.approx(1.0)
    assert scores["rmse"] == 0.0 and scores["depth_rmse_m"] is None


def test_scores_compare_amplitudes_each_normalised_to_its_maximum():
    rng = np.random.default_rng(1)
    reference = _recon(rng.random((8, 10, 12)))
    brighter = _recon(9.0 * reference.intensity)      # amplitude x3: the same once normalised
    scores = reconstruction_scores(reference, brighter)
    assert scores["rmse"] == pytest.approx(0.0, abs=1e-12)
    assert scores["ssim"] == pytest.approx(1.0) and scores["volume_ssim"] == pytest.approx(1.0)
    assert scores["psnr"] > 250


def test_a_dim_voxel_costs_volume_psnr_but_not_the_front_view():
    """Reference: intensity 1 everywhere (amplitude 1). Test: one voxel at intensity 0.25,
    amplitude 0.5, under a column whose other planes are 1: the front view (maximum over
    depth) is unchanged, PSNR inf; the volume's MSE is 0.5^2 / N, PSNR 10 log10(4 N)."""
    ones = np.ones((8, 10, 12))
    dim = ones.copy()
    dim[3, 4, 5] = 0.25
    scores = reconstruction_scores(_recon(ones), _recon(dim))
    assert scores["psnr"] == math.inf and scores["rmse"] == 0.0
    assert scores["volume_psnr"] == pytest.approx(10 * math.log10(4 * ones.size), rel=1e-12)


def test_front_view_psnr_of_a_ghost_on_amplitudes():
    """A ghost of 1% intensity (10% amplitude) beside a unit peak: on amplitudes the front
    view's MSE is 0.1^2 / N; on intensities it would be 0.01^2 / N, 20 dB better."""
    reference = np.zeros((8, 10, 12))
    reference[2, 5, 6] = 1.0
    ghost = reference.copy()
    ghost[4, 1, 1] = 0.01
    scores = reconstruction_scores(_recon(reference), _recon(ghost))
    assert scores["psnr"] == pytest.approx(10 * math.log10(10 * 12 / 0.01), rel=1e-12)


def test_depth_rmse_of_known_depth_errors():
    planes = np.full((10, 12), 3)                     # every column peaks at 0.8 m
    recon = _peaks(planes)
    truth = np.full((10, 12), -1.0)                   # no surface: not counted
    truth[:5] = 0.8                                   # right
    truth[5:, :6] = 1.0                               # 0.2 m too near
    # 60 right and 30 off by 0.2 m over 90 surface pixels: sqrt(30 * 0.04 / 90)
    assert depth_rmse(recon, truth) == pytest.approx(math.sqrt(30 * 0.04 / 90), rel=1e-12)
    shifted = _peaks(np.full((10, 12), 5))            # the whole scene one plane deeper
    assert depth_rmse(shifted, np.full((10, 12), 0.8)) == pytest.approx(0.2, rel=1e-12)
    assert depth_rmse(recon, np.full((10, 12), -1.0)) is None
    scores = reconstruction_scores(recon, shifted, truth_depth=np.full((10, 12), 0.8))
    assert scores["depth_rmse_m"] == pytest.approx(0.2, rel=1e-12)


def test_depth_rmse_resamples_a_finer_truth_map_to_the_voxels():
    """A 20 x 24 truth over the same extent as 10 x 12 voxels: each voxel column takes the
    truth cell holding its centre (rows 2i + 1, columns 2j + 1)."""
    planes = np.full((10, 12), 2)                     # 0.7 m everywhere
    fine = np.full((20, 24), 0.7)
    fine[1::2, 1::2] = 0.9                            # what the voxel centres see
    assert depth_rmse(_peaks(planes), fine) == pytest.approx(0.2, rel=1e-12)
    np.testing.assert_array_equal(resample_nearest(fine, (10, 12)), np.full((10, 12), 0.9))
    coarse = np.arange(6.0).reshape(2, 3)
    np.testing.assert_array_equal(resample_nearest(coarse, (4, 6)),
                                  np.repeat(np.repeat(coarse, 2, axis=0), 2, axis=1))
    with pytest.raises(DataError, match="2-D"):
        resample_nearest(np.zeros(4), (2, 2))


def test_ssim_is_null_below_the_window_and_shapes_must_match():
    small = _recon(np.random.default_rng(2).random((4, 6, 6)))
    scores = reconstruction_scores(small, small)
    assert scores["ssim"] is None and scores["volume_ssim"] is None
    with pytest.raises(DataError, match="differ in shape"):
        reconstruction_scores(small, _recon(np.ones((4, 6, 7))))


def test_ncc_is_pearsons_r_of_the_pixels_and_refuses_what_has_none():
    """The normalised cross-correlation the studies compare front views with: invariant to
    gain and offset, -1 for a negated image, and undefined (a one-line DataError) for a
    constant image or images of different shapes."""
    from nlosfw.evaluation import ncc

    rng = np.random.default_rng(0)
    a, b = rng.random((8, 9)), rng.random((8, 9))
    assert ncc(a, b) == pytest.approx(np.corrcoef(a.ravel(), b.ravel())[0, 1], abs=1e-12)
    assert ncc(a, 3.0 * a + 2.0) == pytest.approx(1.0, abs=1e-12)
    assert ncc(a, -a) == pytest.approx(-1.0, abs=1e-12)
    with pytest.raises(DataError, match="constant"):
        ncc(a, np.ones_like(a))
    with pytest.raises(DataError, match="shape"):
        ncc(a, b[:, :8])


def test_the_scale_invariant_psnr_matches_brightness_before_the_error():
    """One hot voxel halves every other pixel of a normalised front view. Reference
    amplitudes (8 x 8 front view, one plane): 0.5 everywhere, 1 at (0, 0). Test: the same
    halved, with a hot pixel of amplitude 1 at (7, 7), so normalised it reads 0.25 (62
    pixels), 0.5 at (0, 0), 1 at (7, 7). By hand: Σab = 62·0.125 + 0.5 + 0.5 = 8.75,
    Σb² = 62·0.0625 + 0.25 + 1 = 5.125, gain g = 8.75 / 5.125; today's PSNR has MSE
    (62·0.25² + 2·0.5²) / 64; the scale-invariant one the residual a - g b."""
    a = np.full((1, 8, 8), 0.5)
    a[0, 0, 0] = 1.0
    b = a / 2
    b[0, 7, 7] = 1.0
    scores = reconstruction_scores(_recon(a**2), _recon(b**2))     # intensities
    g = 8.75 / 5.125
    assert scores["front_view_gain"] == pytest.approx(g, rel=1e-12)
    plain_mse = (62 * 0.25**2 + 2 * 0.5**2) / 64
    assert scores["psnr"] == pytest.approx(-10 * math.log10(plain_mse), rel=1e-12)
    matched_mse = (62 * (0.5 - g * 0.25) ** 2 + (1 - g * 0.5) ** 2 + (0.5 - g) ** 2) / 64
    assert scores["scale_invariant_psnr"] == pytest.approx(-10 * math.log10(matched_mse),
                                                           rel=1e-12)
    assert scores["scale_invariant_psnr"] > scores["psnr"] + 3.8          # 15.48 vs 11.65 dB


def test_a_dark_test_image_has_no_gain_and_says_why():
    from nlosfw.evaluation.image_scores import scored

    reference = _recon(np.ones((8, 10, 12)))
    values, reasons = scored(reference, _recon(np.zeros((8, 10, 12))))
    assert values["scale_invariant_psnr"] is None and values["front_view_gain"] is None
    assert reasons["front_view_gain"] == ("the image is zero everywhere: no gain matches it "
                                          "to the reference")

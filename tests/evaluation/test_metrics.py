"""Image metrics against closed forms worked out by hand (SSIM and PSNR come from scikit-image)."""

import numpy as np
import pytest

from nlosfw.common.errors import DataError
from nlosfw.evaluation.image_scores import image_metrics, psnr, rmse, ssim


@pytest.mark.parametrize("shape", [(64, 64), (24, 40), (12, 16, 20), (11, 11)])
def test_ssim_of_an_image_with_itself_is_one(shape):
    a = np.random.default_rng(0).random(shape)
    assert ssim(a, a) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("shape", [(32, 32), (12, 16, 20)])
@pytest.mark.parametrize("a, b, data_range", [(0.5, 0.7, 1.0), (0.2, 0.1, 1.0), (3.0, 4.5, 5.0)])
def test_ssim_of_constant_images_is_the_luminance_term(shape, a, b, data_range):
    """Constant images: every window has means a and b and no variance, so SSIM is
    (2ab + C1) / (a^2 + b^2 + C1) with C1 = (0.01 data_range)^2 (the C2 terms cancel)."""
    c1 = (0.01 * data_range) ** 2
    expected = (2 * a * b + c1) / (a * a + b * b + c1)
    got = ssim(np.full(shape, a), np.full(shape, b), data_range=data_range)
    assert got == pytest.approx(expected, rel=1e-12)
    assert expected < 1


def test_gaussian_ssim_of_an_offset_image_is_its_mean_luminance_term():
    """y = x + c: in every window the variances and the covariance agree, so contrast and
    structure give exactly 1 and SSIM is the mean over windows of the luminance term
    1 - c^2 / (mu^2 + (mu + c)^2 + C1), mu the window's Gaussian mean of x (sigma 1.5,
    11 pixels), over the pixels at least 5 from the border."""
    from scipy.ndimage import gaussian_filter

    x = np.random.default_rng(2).random((40, 48)) * 0.5
    c, c1 = 0.1, 1e-4
    mu = gaussian_filter(x, sigma=1.5, truncate=3.5, mode="reflect")[5:-5, 5:-5]
    expected = np.mean(1 - c * c / (mu**2 + (mu + c) ** 2 + c1))
    assert ssim(x, x + c, gaussian=True) == pytest.approx(expected, rel=1e-9)
    # the negative image: same luminance, anti-correlated: (C2 - 2 var) / (C2 + 2 var) < -0.9
    assert -1 < ssim(x, 0.5 - x, gaussian=True) < -0.9


@pytest.mark.parametrize("shape", [(40, 48), (9, 10, 12)])
def test_default_ssim_of_an_offset_image_uses_the_7_pixel_uniform_window(shape):
    """scikit-image's defaults: the same luminance term, with window means over 7 pixels
    per axis (uniform weights), averaged over the pixels at least 3 from the border."""
    from scipy.ndimage import uniform_filter

    x = np.random.default_rng(3).random(shape) * 0.5
    c, c1 = 0.1, 1e-4
    inner = tuple(slice(3, -3) for _ in shape)
    mu = uniform_filter(x, size=7, mode="reflect")[inner]
    expected = np.mean(1 - c * c / (mu**2 + (mu + c) ** 2 + c1))
    assert ssim(x, x + c) == pytest.approx(expected, rel=1e-9)
    if min(shape) >= 11:
        assert ssim(x, x + c) != pytest.approx(ssim(x, x + c, gaussian=True), rel=1e-6)


def test_rmse_psnr_closed_form():
    a = np.zeros((4, 4))
    b = np.full((4, 4), 0.1)
    assert rmse(a, b) == pytest.approx(0.1)
    assert psnr(a, b) == pytest.approx(20.0)        # 20 log10(1 / 0.1)
    assert psnr(a, a) == float("inf")
    half = np.zeros((8, 8))
    half[::2] = 0.2                                 # MSE = 0.04 / 2 = 0.02
    assert psnr(np.zeros((8, 8)), half) == pytest.approx(
        10 * np.log10(1 / 0.02), rel=1e-12)
    assert psnr(np.zeros((8, 8)), half, data_range=2.0) == pytest.approx(
        10 * np.log10(4 / 0.02), rel=1e-12)


def test_image_metrics_normalise_and_handle_small_images():
    rng = np.random.default_rng(1)
    a = rng.random((32, 32))
    scores = image_metrics(a, 7.0 * a)               # same image at another scale
    assert scores["rmse"] == pytest.approx(0.0, abs=1e-12) and scores["ssim"] == pytest.approx(1)
    small = image_metrics(a[:6, :6], a[:6, :6] * 0.5)
    assert small["ssim"] is None and small["rmse"] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(DataError, match="smaller than the 7-pixel window"):
        ssim(a[:6, :6], a[:6, :6])
    with pytest.raises(DataError, match="smaller than the 11-pixel window"):
        ssim(a[:8, :8], a[:8, :8], gaussian=True)

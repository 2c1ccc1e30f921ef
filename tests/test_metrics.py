"""Image metrics against scikit-image's reference implementation and closed forms."""

import numpy as np
import pytest

from nlosfw.common.errors import DataError
from nlosfw.image.scores import image_metrics, psnr, rmse, ssim

skimage_metrics = pytest.importorskip("skimage.metrics")


@pytest.mark.parametrize("shape", [(64, 64), (24, 40), (12, 16, 20)])
def test_ssim_matches_scikit_image(shape):
    rng = np.random.default_rng(0)
    a = rng.random(shape)
    b = np.clip(a + 0.1 * rng.standard_normal(shape), 0, 1)
    expected = skimage_metrics.structural_similarity(
        a, b, data_range=1.0, gaussian_weights=True, sigma=1.5, use_sample_covariance=True)
    assert ssim(a, b) == pytest.approx(expected, rel=1e-10)


def test_rmse_psnr_closed_form():
    a = np.zeros((4, 4))
    b = np.full((4, 4), 0.1)
    assert rmse(a, b) == pytest.approx(0.1)
    assert psnr(a, b) == pytest.approx(20.0)        # 20 log10(1 / 0.1)
    assert psnr(a, a) == float("inf")


def test_image_metrics_normalise_and_handle_small_images():
    rng = np.random.default_rng(1)
    a = rng.random((32, 32))
    scores = image_metrics(a, 7.0 * a)               # same image at another scale
    assert scores["rmse"] == pytest.approx(0.0, abs=1e-12) and scores["ssim"] == pytest.approx(1)
    small = image_metrics(a[:8, :8], a[:8, :8] * 0.5)
    assert small["ssim"] is None and small["rmse"] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(DataError, match="smaller than the 11-pixel window"):
        ssim(a[:8, :8], a[:8, :8])

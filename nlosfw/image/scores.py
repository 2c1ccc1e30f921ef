"""Image metrics for reconstructions: RMSE, PSNR, SSIM (the last two from scikit-image).

Reconstructions from different fields differ in overall scale (fewer wall
samples collect less light), so :func:`image_metrics` compares images each
normalised to a maximum of 1, which is how NLOS reconstructions are displayed.
"""

from __future__ import annotations

import numpy as np

from nlosfw.common.errors import DataError

#: Side of SSIM's Gaussian window (sigma 1.5 truncated at 3.5 sigma): smaller images have none.
SSIM_WINDOW = 11


def normalise(image: np.ndarray) -> np.ndarray:
    """``image / max(image)`` (zeros stay zeros)."""
    image = np.asarray(image, dtype=np.float64)
    peak = float(np.max(image)) if image.size else 0.0
    return image / peak if peak > 0 else np.zeros_like(image)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """Root-mean-square difference."""
    a, b = _pair(a, b)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def psnr(reference: np.ndarray, test: np.ndarray, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio 10 log10(data_range^2 / MSE) in dB (inf for identical images).

    scikit-image's ``peak_signal_noise_ratio``.
    """
    a, b = _pair(reference, test)
    if np.array_equal(a, b):
        return float("inf")                    # scikit-image would warn about log10(0)
    from skimage.metrics import peak_signal_noise_ratio

    return float(peak_signal_noise_ratio(a, b, data_range=data_range))


def ssim(reference: np.ndarray, test: np.ndarray, data_range: float = 1.0,
         sigma: float = 1.5) -> float:
    """Mean structural similarity (Wang et al. 2004) with a Gaussian window, 2D or 3D.

    scikit-image's ``structural_similarity`` with ``gaussian_weights=True``: constants
    K1 = 0.01, K2 = 0.03, sample covariances, window truncated at 3.5 sigma (11 pixels
    for sigma 1.5), borders excluded from the mean. DataError when a side of the
    images is shorter than the window.
    """
    x, y = _pair(reference, test)
    win = 2 * int(3.5 * sigma + 0.5) + 1      # scikit-image's window: SSIM_WINDOW for 1.5
    if min(x.shape) < win:
        raise DataError(f"ssim: images of shape {x.shape} are smaller than the {win}-pixel window")
    from skimage.metrics import structural_similarity

    return float(structural_similarity(x, y, data_range=data_range, gaussian_weights=True,
                                       sigma=sigma, use_sample_covariance=True))


def image_metrics(reference: np.ndarray, test: np.ndarray) -> dict[str, float | None]:
    """RMSE, PSNR and SSIM of ``test`` against ``reference``, both normalised to max 1.

    SSIM is None for images smaller than its 11-pixel window (it is undefined there).
    """
    a, b = normalise(reference), normalise(test)
    small = min(a.shape) < SSIM_WINDOW
    return {"rmse": rmse(a, b), "psnr": psnr(a, b), "ssim": None if small else ssim(a, b)}


def _pair(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise DataError(f"images differ in shape: {a.shape} vs {b.shape}")
    return a, b

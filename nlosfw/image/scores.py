"""Image metrics for reconstructions: RMSE, PSNR, SSIM.

Reconstructions from different fields differ in overall scale (fewer wall
samples collect less light), so :func:`image_metrics` compares images each
normalised to a maximum of 1, which is how NLOS reconstructions are displayed.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

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
    """Peak signal-to-noise ratio in dB (inf for identical images)."""
    error = rmse(reference, test)
    return float("inf") if error == 0 else float(20 * np.log10(data_range / error))


def ssim(reference: np.ndarray, test: np.ndarray, data_range: float = 1.0,
         sigma: float = 1.5) -> float:
    """Mean structural similarity (Wang et al. 2004) with a Gaussian window.

    Constants K1 = 0.01, K2 = 0.03, sample covariances, window truncated at
    3.5 sigma, borders excluded as in scikit-image's ``gaussian_weights=True``.
    Works for 2D and 3D images.
    """
    x, y = _pair(reference, test)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    truncate = 3.5
    n = x.ndim
    win = 2 * int(truncate * sigma + 0.5) + 1  # SSIM_WINDOW for the default sigma
    if min(x.shape) < win:
        raise DataError(f"ssim: images of shape {x.shape} are smaller than the {win}-pixel window")
    cov_norm = win**n / (win**n - 1)

    def blur(img: np.ndarray) -> np.ndarray:
        return gaussian_filter(img, sigma=sigma, truncate=truncate, mode="reflect")

    ux, uy = blur(x), blur(y)
    vx = cov_norm * (blur(x * x) - ux * ux)
    vy = cov_norm * (blur(y * y) - uy * uy)
    vxy = cov_norm * (blur(x * y) - ux * uy)
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux**2 + uy**2 + c1) * (vx + vy + c2))
    pad = (win - 1) // 2
    inner = tuple(slice(pad, dim - pad) for dim in s.shape)
    return float(s[inner].mean())


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

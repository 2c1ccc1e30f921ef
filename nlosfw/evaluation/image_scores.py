"""Scores of reconstructions: PSNR and SSIM (scikit-image), RMSE, and depth RMSE.

The only module of nlosfw that imports ``skimage.metrics``.

:func:`reconstruction_scores` is what every run reports for each source against the
reconstruction of the full capture, as the sparse-scan NLOS papers score theirs: on
amplitudes (the square root of a reconstruction's intensity), each normalised to its
maximum (reconstructions from different fields differ in overall scale: fewer wall
samples collect less light), with scikit-image's ``peak_signal_noise_ratio(a, b,
data_range=1)`` and ``structural_similarity(a, b, data_range=1)`` at their defaults
(a 7-pixel uniform window, sample covariances). Amplitudes rather than intensities,
because squaring hides faint ghosts that a sparse scan's image holds (measured on
``letter_t``: ``studies/sparse_scans_simulated/README.md``).

:func:`ssim` also offers Wang et al.'s 11-pixel Gaussian window (``gaussian=True``),
the variant some papers report; the run's scores never use it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from nlosfw.common.errors import DataError
from nlosfw.evaluation.undefined import Scored
from nlosfw.image.reconstruction import Reconstruction

#: Side of scikit-image's default SSIM window: smaller images (or volumes) have no SSIM.
SSIM_WINDOW = 7


def normalise(image: np.ndarray) -> np.ndarray:
    """``image / max(image)`` (zeros stay zeros)."""
    image = np.asarray(image, dtype=np.float64)
    peak = float(np.max(image)) if image.size else 0.0
    return image / peak if peak > 0 else np.zeros_like(image)


def amplitude(intensity: np.ndarray) -> np.ndarray:
    """The square root of an intensity (negative rounding errors read as 0)."""
    return np.sqrt(np.clip(np.asarray(intensity, dtype=np.float64), 0.0, None))


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """Root-mean-square difference."""
    a, b = _pair(a, b)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def ncc(reference: np.ndarray, test: np.ndarray) -> float:
    """Normalised cross-correlation of two images of one shape: Pearson's r of their pixels
    (1 for the same image up to gain and offset). A constant image has none: DataError."""
    a, b = _pair(reference, test)
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    norm = float(np.linalg.norm(a) * np.linalg.norm(b))
    if norm == 0.0:
        raise DataError("ncc: an image is constant; its correlation is undefined")
    return float(a @ b / norm)


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
         gaussian: bool = False, sigma: float = 1.5) -> float:
    """Mean structural similarity (Wang et al. 2004) of two images or volumes.

    scikit-image's ``structural_similarity`` with constants K1 = 0.01, K2 = 0.03,
    sample covariances and borders excluded from the mean. By default its defaults: a
    uniform window of :data:`SSIM_WINDOW` pixels per axis. ``gaussian``: a Gaussian
    window of standard deviation ``sigma`` truncated at 3.5 sigma (11 pixels for 1.5).
    DataError when a side of the images is shorter than the window.
    """
    x, y = _pair(reference, test)
    win = 2 * int(3.5 * sigma + 0.5) + 1 if gaussian else SSIM_WINDOW
    if min(x.shape) < win:
        raise DataError(f"ssim: images of shape {x.shape} are smaller than the {win}-pixel window")
    from skimage.metrics import structural_similarity

    if gaussian:
        return float(structural_similarity(x, y, data_range=data_range, gaussian_weights=True,
                                           sigma=sigma, use_sample_covariance=True))
    return float(structural_similarity(x, y, data_range=data_range))


def least_squares_gain(reference: np.ndarray, test: np.ndarray) -> float | None:
    """The gain g minimising ``|reference - g test|²`` (None when ``test`` is zero
    everywhere): above 1, ``test`` is the darker."""
    a, b = _pair(reference, test)
    power = float(np.sum(b * b))
    return float(np.sum(a * b)) / power if power > 0 else None


def scale_invariant_psnr(reference: np.ndarray, test: np.ndarray) -> float | None:
    """PSNR (data range 1) of ``test`` times its :func:`least_squares_gain` against
    ``reference``, both normalised to max 1: the error left once the overall brightness
    is matched, so that a few hot voxels that set one image's maximum do not move the
    score of every pixel. None when ``test`` is zero everywhere."""
    return brightness_matched(reference, test)[0]


def brightness_matched(reference: np.ndarray, test: np.ndarray
                       ) -> tuple[float | None, float | None]:
    """(:func:`scale_invariant_psnr`, the :func:`least_squares_gain` it applies) of ``test``
    against ``reference``, both normalised to max 1 once."""
    a, b = normalise(reference), normalise(test)
    gain = least_squares_gain(a, b)
    return (None if gain is None else psnr(a, gain * b)), gain


def image_metrics(reference: np.ndarray, test: np.ndarray) -> dict[str, float | None]:
    """RMSE, PSNR and SSIM (scikit-image's defaults) of ``test`` against ``reference``,
    images or volumes, both normalised to max 1.

    SSIM is None for images smaller than its 7-pixel window (it is undefined there).
    """
    a, b = normalise(reference), normalise(test)
    small = min(a.shape) < SSIM_WINDOW
    return {"rmse": rmse(a, b), "psnr": psnr(a, b), "ssim": None if small else ssim(a, b)}


def reconstruction_scores(reference: Reconstruction, test: Reconstruction,
                          truth_depth: np.ndarray | None = None) -> dict[str, float | None]:
    """The scores of ``test`` against ``reference`` (both planes or volumes on the same voxels).

    On amplitudes, each normalised to its maximum: ``rmse``, ``psnr`` and ``ssim`` of the
    front view (the maximum over depth, (Y, X)); ``scale_invariant_psnr`` of the front view
    and its ``front_view_gain`` (:func:`scale_invariant_psnr`, :func:`least_squares_gain`);
    ``volume_psnr`` and ``volume_ssim`` of the whole (Z, Y, X) volume; ``depth_rmse_m``
    against ``truth_depth`` (see :func:`depth_rmse`), None without one. An SSIM is None
    where the image is smaller than the 7-pixel window; a PSNR is inf for identical
    images.
    """
    ref, tst = amplitude(reference.as_volume()[0]), amplitude(test.as_volume()[0])
    if ref.shape != tst.shape:
        raise DataError(f"reconstructions differ in shape: {ref.shape} vs {tst.shape}")
    front_ref, front_tst = ref.max(axis=0), tst.max(axis=0)
    front = image_metrics(front_ref, front_tst)
    volume = image_metrics(ref, tst)
    matched_psnr, gain = brightness_matched(front_ref, front_tst)
    return {**front, "scale_invariant_psnr": matched_psnr, "front_view_gain": gain,
            "volume_psnr": volume["psnr"], "volume_ssim": volume["ssim"],
            "depth_rmse_m": None if truth_depth is None else depth_rmse(test, truth_depth)}


def scored(reference: Reconstruction, test: Reconstruction,
           truth_depth: np.ndarray | None = None) -> Scored:
    """:func:`reconstruction_scores` as a run records them: every score a finite number or
    None, and why each None is (by score name; ``depth_rmse_m`` only with a
    ``truth_depth``)."""
    values = reconstruction_scores(reference, test)
    ref, tst = amplitude(reference.as_volume()[0]), amplitude(test.as_volume()[0])
    front = (ref.max(axis=0), tst.max(axis=0))
    views = {"psnr": front, "ssim": front, "scale_invariant_psnr": front,
             "front_view_gain": front, "volume_psnr": (ref, tst), "volume_ssim": (ref, tst)}
    reasons: dict[str, str] = {}
    for name, (a, b) in views.items():
        value = values[name]
        if value is not None and math.isfinite(value):
            continue
        values[name] = None
        reasons[name] = _undefined_image_score(name, value, a, b)
    if truth_depth is not None:
        values["depth_rmse_m"], reason = depth_error(test, truth_depth)
        if reason is not None:
            reasons["depth_rmse_m"] = reason
    return Scored(values, reasons)


def _undefined_image_score(name: str, value: float | None, a: np.ndarray,
                           b: np.ndarray) -> str:
    """Why score ``name`` (None or not finite) of images ``a`` and ``b`` is undefined."""
    if value is None and name in ("scale_invariant_psnr", "front_view_gain"):
        return "the image is zero everywhere: no gain matches it to the reference"
    if value is None and name.endswith("ssim"):
        return (f"the image ({' x '.join(map(str, a.shape))}) is smaller than SSIM's "
                f"{SSIM_WINDOW}-pixel window")
    if value == math.inf:
        if not np.any(a > 0) and not np.any(b > 0):
            return "both images are zero everywhere: no error, so no finite PSNR"
        return "identical images (each normalised to its maximum): no error, so no finite PSNR"
    return f"not a number ({value}) on these images"


def depth_rmse(recon: Reconstruction, truth_depth: np.ndarray) -> float | None:
    """RMS error (m) of the depth of the brightest voxel in each (y, x) column of ``recon``
    against ``truth_depth``, over the pixels where the truth has a surface (depth > 0).

    ``truth_depth`` is a (Y', X') image (y along rows) covering the same lateral extent
    as the voxel planes (the relay wall, as the pipeline's voxels and a simulated
    scene's ground truth both do); a different resolution is resampled to the voxels'
    (Y, X) by nearest cell centre. None when it cannot be computed
    (:func:`depth_error` says why): the truth has no surface, or a column of ``recon``
    at a surface pixel is dark (zero), so it has no brightest voxel.
    """
    return depth_error(recon, truth_depth)[0]


def depth_error(recon: Reconstruction, truth_depth: np.ndarray) -> tuple[float | None,
                                                                        str | None]:
    """(:func:`depth_rmse`, None), or (None, why it cannot be computed)."""
    depth = recon.depth_map(threshold=0.0)
    truth = resample_nearest(np.asarray(truth_depth, dtype=np.float64), depth.shape)
    surface = np.isfinite(truth) & (truth > 0)
    if not np.any(surface):
        return None, "the scene's true depth has no surface in the voxels' view"
    dark = int(np.count_nonzero(~np.isfinite(depth[surface])))
    if dark == int(np.count_nonzero(surface)) and not np.any(np.isfinite(depth)):
        return None, "the reconstruction is zero everywhere: no voxel is brightest, so no depth"
    if dark:
        return None, (f"the reconstruction is zero at {dark} of the "
                      f"{int(np.count_nonzero(surface))} pixels where the scene has a surface: "
                      "they have no depth")
    return float(np.sqrt(np.mean((depth[surface] - truth[surface]) ** 2))), None


def resample_nearest(image: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``image`` (Y', X') on a (Y, X) grid of cells over the same extent, each new cell
    taking the value of the old cell that holds its centre."""
    image = np.asarray(image)
    if image.ndim != 2 or len(shape) != 2:
        raise DataError(f"resample: need a 2-D image and shape, got {image.shape} -> {shape}")
    if image.shape == tuple(shape):
        return image
    rows = _nearest_cells(image.shape[0], shape[0])
    cols = _nearest_cells(image.shape[1], shape[1])
    return image[np.ix_(rows, cols)]


def _nearest_cells(n_old: int, n_new: int) -> np.ndarray:
    return np.minimum(((np.arange(n_new) + 0.5) * n_old / n_new).astype(np.int64), n_old - 1)


def _pair(a: npt.ArrayLike, b: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise DataError(f"images differ in shape: {a.shape} vs {b.shape}")
    return a, b

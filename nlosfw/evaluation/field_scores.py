"""Field scores: a prediction of the full field against the true one, on the sets of the
protocol (held-out pixels at training frequencies, every pixel at held-out frequencies,
everything), a prediction's gain against the noise-free field (:func:`denoising_errors`),
and the parameters/data ratio of thesis Table 4.1."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from nlosfw.common.errors import ConfigError, DataError
from nlosfw.evaluation.splits import FieldSplit
from nlosfw.evaluation.undefined import Scored
from nlosfw.transform.field import PhasorField


def error_metrics(true: np.ndarray, predicted: np.ndarray) -> dict[str, Any]:
    """Errors of complex ``predicted`` against ``true`` (same shape), over all their elements.

    * ``relative_l2``: ||P^ - P|| / ||P|| (complex L2 norms);
    * ``nmse_db``: 10 log10(||P^ - P||^2 / ||P||^2) = 20 log10(relative_l2);
    * ``amplitude_rmse``: sqrt(mean((|P^| - |P|)^2)) in the field's units, and
      ``relative_amplitude_rmse``, the same divided by sqrt(mean(|P|^2));
    * ``phase_error``: sum(|P| |wrap(arg P^ - arg P)|) / sum(|P|), radians in [0, pi].

    Values are None when the set is empty; ``n_samples`` counts complex samples.
    """
    t = np.asarray(true, dtype=np.complex128).ravel()
    p = np.asarray(predicted, dtype=np.complex128).ravel()
    if t.shape != p.shape:
        raise DataError(f"error_metrics: shapes differ: true {t.shape}, predicted {p.shape}")
    empty = {"relative_l2": None, "nmse_db": None, "amplitude_rmse": None,
             "relative_amplitude_rmse": None, "phase_error": None, "n_samples": 0}
    if t.size == 0:
        return empty
    err2 = float(np.sum(np.abs(p - t) ** 2))
    ref2 = float(np.sum(np.abs(t) ** 2))
    rel = math.sqrt(err2 / ref2) if ref2 > 0 else math.inf
    mag_t, mag_p = np.abs(t), np.abs(p)
    amp_rmse = float(np.sqrt(np.mean((mag_p - mag_t) ** 2)))
    rms = math.sqrt(ref2 / t.size)
    dphi = np.abs(np.angle(p * np.conj(t)))
    phase = float(np.sum(mag_t * dphi) / np.sum(mag_t)) if ref2 > 0 else math.nan
    return {
        "relative_l2": rel,
        "nmse_db": 10 * math.log10(err2 / ref2) if ref2 > 0 and err2 > 0 else (
            -math.inf if ref2 > 0 else math.inf),
        "amplitude_rmse": amp_rmse,
        "relative_amplitude_rmse": amp_rmse / rms if rms > 0 else math.inf,
        "phase_error": phase,
        "n_samples": int(t.size),
    }


def field_metrics(true_field: PhasorField | np.ndarray, predicted_field: PhasorField | np.ndarray,
                  split: FieldSplit) -> dict[str, dict[str, Any]]:
    """Errors of a prediction of the full field on the three sets of the protocol.

    ``true_field`` and ``predicted_field`` are the full fields (or their complex
    ``values`` arrays, shape (F, Y, X)) that ``split`` was made from. Returns
    ``{"heldout_pixels": ..., "heldout_frequencies": ..., "all": ...}``, each the dict
    of :func:`error_metrics`: held-out pixels at training frequencies, every pixel at
    held-out frequencies, and every sample; plus ``heldout_pixels_inside``, the held-out
    pixels inside the training pixels' bounding box (with the default split the last
    row and column lie outside it, half a training step beyond: an extrapolation that
    often dominates ``heldout_pixels``). Sets that are empty (no spatial or no spectral
    hold-out) have None values.
    """
    if not isinstance(split, FieldSplit):
        raise ConfigError("split", f"field_metrics needs the FieldSplit the fields were split "
                                   f"by (split_field's), got {type(split).__name__}")
    t = _field_values(true_field, "true_field")
    p = _field_values(predicted_field, "predicted_field")
    if t.shape != p.shape or t.ndim != 3:
        raise DataError(f"field_metrics: true {t.shape} and predicted {p.shape} must both be the "
                        "full (frequency, y, x) field")
    if t.shape[1:] != split.spatial_mask.shape:
        raise DataError(f"field_metrics: the fields' grid {t.shape[1:]} is not the split's "
                        f"{split.spatial_mask.shape}")
    n_f = split.train_frequencies.size + split.heldout_frequencies.size
    if t.shape[0] != n_f:
        raise DataError(f"field_metrics: the fields have {t.shape[0]} frequencies, the split "
                        f"{n_f}")
    held_px = ~split.spatial_mask
    inside = held_px & hull_mask(split.spatial_mask)
    tf, hf = split.train_frequencies, split.heldout_frequencies
    return {
        "heldout_pixels": error_metrics(t[tf][:, held_px], p[tf][:, held_px]),
        "heldout_frequencies": error_metrics(t[hf], p[hf]),
        "all": error_metrics(t, p),
        "heldout_pixels_inside": error_metrics(t[tf][:, inside], p[tf][:, inside]),
    }


def _field_values(field: object, option: str) -> np.ndarray:
    """The complex values of a PhasorField or of a numeric array; a ConfigError naming
    ``option`` for anything else."""
    if isinstance(field, PhasorField):
        return field.values
    try:
        values = np.asarray(field) if isinstance(field, (np.ndarray, list, tuple)) else None
    except (TypeError, ValueError):          # a ragged list
        values = None
    if values is None or values.dtype.kind not in "biufc" or values.ndim != 3:
        got = (type(field).__name__ if values is None
               else f"an array of shape {values.shape} of {values.dtype}")
        raise ConfigError(option, f"expected a PhasorField or its values (F, Y, X), got {got}")
    return values


def hull_mask(spatial_mask: np.ndarray) -> np.ndarray:
    """Pixels inside the bounding box of the training pixels (rows and columns between the
    first and last ones holding a training pixel)."""
    rows = np.flatnonzero(spatial_mask.any(axis=1))
    cols = np.flatnonzero(spatial_mask.any(axis=0))
    out = np.zeros_like(spatial_mask, dtype=bool)
    if rows.size and cols.size:
        out[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1] = True
    return out


def parameter_data_ratio(n_parameters: int, n_values: int | FieldSplit) -> float:
    """Parameters per training value in percent (thesis Table 4.1's "Parameters/Data (%)").

    ``n_values`` counts real values (2 per complex sample) or is a :class:`FieldSplit`.
    E.g. SIREN, 3362 parameters, 32 x 32 x 135 x 2 = 276,480 values: 1.22%.
    """
    n = n_values.n_train_values if isinstance(n_values, FieldSplit) else int(n_values)
    if n <= 0:
        raise DataError(f"parameter_data_ratio: need a positive number of values, got {n}")
    return 100.0 * int(n_parameters) / n


#: The names of :func:`denoising_errors`'s scores.
DENOISING = ("noisy_relative_l2", "relative_l2", "gain_db")


def denoising_errors(clean: PhasorField, noisy: PhasorField, predicted: PhasorField) -> Scored:
    """Errors against the noise-free field ``clean``: of the ``noisy`` full field
    (``noisy_relative_l2``), of a prediction (``relative_l2``), and the gain, 20 log10 of
    their ratio (``gain_db``); None, with why, where undefined (a zero noise-free field,
    an error of zero)."""
    norm = float(np.linalg.norm(clean.values))
    if not norm > 0:
        why = "the noise-free field is zero (the scene reflects nothing): no error relative to it"
        return Scored(dict.fromkeys(DENOISING), dict.fromkeys(DENOISING, why))

    def rel(field: PhasorField) -> float:
        return float(np.linalg.norm(field.values - clean.values)) / norm

    noisy_error, model_error = rel(noisy), rel(predicted)
    if noisy_error > 0 and model_error > 0:
        return Scored({"noisy_relative_l2": noisy_error, "relative_l2": model_error,
                       "gain_db": float(20 * np.log10(noisy_error / model_error))}, {})
    why = ("the prediction equals the noise-free field: the gain is infinite"
           if model_error == 0 else "the noisy field equals the noise-free field (no noise)")
    return Scored({"noisy_relative_l2": noisy_error, "relative_l2": model_error,
                   "gain_db": None}, {"gain_db": why})

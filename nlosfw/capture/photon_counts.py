"""A capture's photon counts: H as integers (what count splitting, the pile-up correction
and the Poisson likelihood need), the count scale of a simulated capture and the Poisson
variance of each bin.

A simulated noisy capture stores its counts divided by ``scene_info.noise.counts_per_unit``
(photons per unit of H): its counts are H times that scale.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.errors import ConfigError, DataError

#: The most photons a capture may hold in all: 2^53 - 1, so that every count and their sum
#: are exact in float64 (a float64 sum of integer counts is exact below 2^53, and at least
#: 2^53 above) and far from the end of int64 (beyond it, a total wrapped to a negative
#: number, and a count cast to int64 to a negative one).
MAX_PHOTONS = 2**53 - 1

#: How far, relative to itself, a stored value may be from an integer and still count as
#: one (a simulated capture's counts went through a float32 division by its scale).
_RELATIVE_TOLERANCE = 1e-4


def count_scale(capture: Capture) -> float:
    """Photon counts per unit of H: ``scene_info.noise.counts_per_unit`` of a simulated
    Poisson capture, else 1 (a file's raw counts)."""
    noise = capture.scene_info.get("noise")
    if isinstance(noise, Mapping) and noise.get("model") == "poisson":
        scale = noise.get("counts_per_unit")
        if isinstance(scale, (int, float)) and np.isfinite(scale) and scale > 0:
            return float(scale)
    return 1.0


def photon_counts(capture: Capture, where: str, option: str, purpose: str) -> np.ndarray:
    """H as integer photon counts (int64), or a one-line error naming ``where`` (the
    capture) and ``option`` (the step that needs them, ``purpose``): a ConfigError when H
    is not counts (complex, not finite, negative, or not integers after the count scale of
    a simulated capture), a DataError when it holds more than :data:`MAX_PHOTONS` in all."""
    H = capture.H
    if np.iscomplexobj(H):
        raise ConfigError(option, f"{where}: H is complex (a frequency-domain capture); "
                                  f"{purpose} needs photon counts")
    if np.issubdtype(H.dtype, np.integer):
        if H.size and int(H.min()) < 0:
            raise ConfigError(option, f"{where}: H holds negative values (min {int(H.min())}); "
                                      f"{purpose} needs photon counts >= 0")
        _check_total(H.astype(np.float64), 1.0, where, option, purpose)
        return H.astype(np.int64)
    if not np.all(np.isfinite(H)):
        raise ConfigError(option, f"{where}: H holds NaN or infinite values; {purpose} "
                                  "needs photon counts")
    scale = count_scale(capture)
    with np.errstate(over="ignore"):            # beyond float64: refused as too many below
        values = H.astype(np.float64) * scale
    low = float(values.min()) if values.size else 0.0
    if low < 0:
        raise ConfigError(option, f"{where}: H holds negative values (min {low:.4g}), e.g. after "
                                  f"a background subtraction; {purpose} needs raw photon "
                                  "counts >= 0")
    _check_total(values, scale, where, option, purpose)
    counts = np.rint(values)
    distance = np.abs(values - counts)
    bad = distance > _RELATIVE_TOLERANCE * np.abs(values) + 1e-9
    if np.any(bad):
        off = float(distance[bad].max())
        raise ConfigError(option, f"{where}: H{_per(scale)} is not integer photon counts (a value "
                                  f"is {off:.3g} from the nearest integer); {purpose} needs raw "
                                  "counts, before any step that does not keep them integers")
    return np.maximum(counts, 0).astype(np.int64)


def count_variance(capture: Capture) -> np.ndarray:
    """The variance of each bin of a capture of Poisson counts, in the units of H squared,
    estimated by its own counts: Var(n / s) = n / s^2 = H / s (float64, H's shape)."""
    return np.asarray(capture.H, dtype=np.float64) / count_scale(capture)


def _per(scale: float) -> str:
    return "" if scale == 1.0 else f" times its {scale:.4g} counts per unit"


def _check_total(values: np.ndarray, scale: float, where: str, option: str,
                 purpose: str) -> None:
    """A DataError naming ``where`` when the counts ``values`` (>= 0, float64) add up to
    more than :data:`MAX_PHOTONS` (or beyond float64)."""
    with np.errstate(over="ignore"):
        total = float(values.sum())
    if not total <= MAX_PHOTONS:
        raise DataError(f"{where}: H{_per(scale)} holds {total:.4g} photon counts in all, more "
                        f"than {MAX_PHOTONS} (2^53 - 1: beyond, counts are not exact numbers); "
                        f"{purpose} ({option}) needs the raw photon counts of a measurement")

"""Count splitting (binomial thinning): one capture of photon counts as two independent ones.

Each bin's count n is split into a ~ Binomial(n, 1/2) and b = n - a. When n is Poisson with
mean mu, a and b are independent Poisson counts with mean mu / 2 each: two captures (A and
B) of the same scan at half the exposure, whose noises are independent. A model trained on
A and scored against B is not rewarded for copying A's noise, and B's own noise is known
(its variance is its mean, estimated by its counts), which gives the error a perfect
predictor would make: the noise floor (:mod:`nlosfw.transform.noise_floor`).

Valid on raw integer counts and any step that keeps them integers (gate, crop, bin, stride,
integer shifts, transpose and flip), not after a background subtraction. Only
approximate where the counts are not Poisson: under dead time and pile-up (a SPAD in
histogram mode at high flux), and when the scan points were not each measured for the
same dwell time (the split halves every point's exposure, the sampling assumes equal
ones).

A simulated noisy capture stores its counts divided by ``scene_info.noise.counts_per_unit``
(photons per unit of H): its counts are H times that scale, and its halves are divided back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.config import require_seed
from nlosfw.common.errors import ConfigError, DataError

#: The option that turns count splitting on (named in every refusal).
OPTION = "split.thinning"

#: The most photons a capture may hold in all: 2^53 - 1, so that every count and their sum
#: are exact in float64 (a float64 sum of integer counts is exact below 2^53, and at least
#: 2^53 above) and far from the end of int64 (beyond it, a total wrapped to a negative
#: number, and a count cast to int64 to a negative one).
MAX_PHOTONS = 2**53 - 1

#: Below this many photons the split is drawn before the run (:func:`check_split`).
DRAWN_BELOW = 64

#: How far, relative to itself, a stored value may be from an integer and still count as
#: one (a simulated capture's counts went through a float32 division by its scale).
_RELATIVE_TOLERANCE = 1e-4


@dataclass(frozen=True, eq=False)
class ThinnedCapture:
    """The two halves of a capture of counts: ``a`` trains, ``b`` scores."""

    a: Capture
    b: Capture
    seed: int
    count_scale: float
    """Photon counts per unit of H (1 for a file of raw counts)."""
    counts_a: int
    counts_b: int


def count_scale(capture: Capture) -> float:
    """Photon counts per unit of H: ``scene_info.noise.counts_per_unit`` of a simulated
    Poisson capture, else 1 (a file's raw counts)."""
    noise = capture.scene_info.get("noise")
    if isinstance(noise, Mapping) and noise.get("model") == "poisson":
        scale = noise.get("counts_per_unit")
        if isinstance(scale, (int, float)) and np.isfinite(scale) and scale > 0:
            return float(scale)
    return 1.0


def photon_counts(capture: Capture, where: str, option: str = OPTION,
                  purpose: str = "count splitting") -> np.ndarray:
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


def check_split(capture: Capture, seed: int, where: str) -> None:
    """A one-line error naming ``where`` unless count splitting with ``seed`` leaves both
    halves photons: a ConfigError for ``split.thinning`` when the capture holds fewer than
    two (or is not counts, :func:`photon_counts`), for ``split.thinning_seed`` when every
    photon goes to one half. The halves are drawn only for fewer than
    :data:`DRAWN_BELOW` photons: with more, a half is empty with probability below 2^-63."""
    total = int(photon_counts(capture, where).sum())
    if total < 2:
        raise ConfigError(OPTION, f"{where}: holds {total} photon{'' if total == 1 else 's'} "
                                  "(after its preprocessing); count splitting needs at least 2, "
                                  "one for each half (training and scoring)")
    if total < DRAWN_BELOW:
        halves = thin(capture, seed, where)
        if 0 in (halves.counts_a, halves.counts_b):
            empty, use = ("A", "trains the models") if halves.counts_a == 0 else (
                "B", "scores them")
            raise ConfigError("split.thinning_seed", f"{where}: with seed {seed} all its "
                              f"{total} photons go to one half, leaving half {empty} (which "
                              f"{use}) none; choose another seed or a capture with more "
                              "photons")


def thin(capture: Capture, seed: int, where: str = "the capture") -> ThinnedCapture:
    """Split every bin's count n into Binomial(n, 1/2) (capture A) and the rest (B), drawn
    with ``seed`` (0 to 2^63 - 1); both keep H's dtype and units (counts divided by the
    count scale)."""
    require_seed(seed, "split.thinning_seed")
    counts = photon_counts(capture, where)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7417]))
    a = rng.binomial(counts, 0.5)
    b = counts - a
    scale = count_scale(capture)
    return ThinnedCapture(a=_half(capture, a, scale, "A", seed),
                          b=_half(capture, b, scale, "B", seed), seed=int(seed),
                          count_scale=scale, counts_a=int(a.sum()), counts_b=int(b.sum()))


def count_variance(capture: Capture) -> np.ndarray:
    """The variance of each bin of a capture of Poisson counts, in the units of H squared,
    estimated by its own counts: Var(n / s) = n / s^2 = H / s (float64, H's shape)."""
    return np.asarray(capture.H, dtype=np.float64) / count_scale(capture)


def _half(capture: Capture, counts: np.ndarray, scale: float, name: str, seed: int) -> Capture:
    dtype = capture.H.dtype
    H = (counts.astype(dtype) if np.issubdtype(dtype, np.integer)
         else (counts / scale).astype(dtype))
    info = dict(capture.scene_info)
    info["thinning"] = {"half": name, "seed": int(seed), "probability": 0.5}
    return capture.replace(H=H, scene_info=info)

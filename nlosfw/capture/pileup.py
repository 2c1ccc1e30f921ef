"""Pile-up of a single-photon detector in histogram mode, and its correction (Coates, 1968).

A SPAD with a time-correlated counter records at most the first photon of each laser
pulse (the rest arrive in its dead time). With lambda_i the mean number of photons one
pulse brings into bin i (Poisson), the probability that a pulse's first detection falls in
bin i is

    p_i = exp(-sum_{j<i} lambda_j) (1 - exp(-lambda_i)),

so after N pulses a bin's expected count is N p_i: the early bins (the direct reflection,
a bright object) hide the later ones. Pile-up multiplies the signal; it is not a
background. Coates' estimator inverts it bin by bin from the counts n_i,

    lambda_i = -ln(1 - n_i / (N - sum_{j<i} n_j)),

and N lambda_i, what an ideal detector would have counted over the same pulses, replaces
n_i. It is unbiased only where the counts are large; a bin that took every pulse still
alive has no finite estimate, so the pulses must exceed every scan point's total count.

The bins must be in the order the detector recorded them, from the pulse on: correct
before any step that zeroes, crops or shifts the time axis (``capture.pileup_pulses`` is
the first preprocessing step). Counts before a file's first bin are taken as none.
"""

from __future__ import annotations

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.photon_counts import count_scale, photon_counts
from nlosfw.common.errors import ConfigError

#: The option that turns the correction on (named in every refusal).
OPTION = "capture.pileup_pulses"


def first_photon_probabilities(rates: np.ndarray) -> np.ndarray:
    """p_i of the module docstring: the probability that a pulse's first photon falls in
    bin i, for ``rates`` lambda_i >= 0 (mean photons per pulse; time on axis 0). One minus
    their sum is the probability of no detection, exp(-sum_i lambda_i)."""
    lam = np.asarray(rates, dtype=np.float64)
    before = np.cumsum(lam, axis=0) - lam                   # sum over the earlier bins
    return np.exp(-before) * -np.expm1(-lam)


def coates_rates(counts: np.ndarray, pulses: float) -> np.ndarray:
    """Coates' estimate of lambda_i (mean photons per pulse in bin i; time on axis 0) from
    the first-photon counts of ``pulses`` pulses. Every histogram's total must be below
    ``pulses`` (a ValueError otherwise: a bin with no pulse left has no estimate)."""
    n = np.asarray(counts, dtype=np.float64)
    alive = pulses - (np.cumsum(n, axis=0) - n)             # pulses with no detection yet
    if np.any(n.sum(axis=0) >= pulses):
        raise ValueError(f"a histogram holds {n.sum(axis=0).max():.0f} counts, not fewer than "
                         f"the {pulses:g} pulses")
    return -np.log1p(-n / alive)


def correct_pileup(capture: Capture, pulses: int, where: str = "the capture") -> Capture:
    """``capture`` with its counts replaced by Coates' estimate of what an ideal detector
    would have counted over ``pulses`` laser pulses per scan point, in H's units (counts
    over the count scale of a simulated capture). A one-line ConfigError naming
    ``capture.pileup_pulses`` and ``where`` when H is not photon counts, or when a scan
    point holds as many counts as pulses (the smallest valid value is said)."""
    counts = photon_counts(capture, where, option=OPTION, purpose="pile-up correction")
    totals = counts.sum(axis=0)
    most = int(totals.max()) if totals.size else 0
    if most >= pulses:
        raise ConfigError(OPTION, f"{where}: a scan point holds {most} counts, at least the "
                                  f"{pulses} pulses given (each pulse records one photon at "
                                  f"most); valid: the laser pulses per scan point, more than "
                                  f"{most}")
    rates = coates_rates(counts, pulses)
    H = (rates * (pulses / count_scale(capture))).astype(capture.H.dtype)
    info = dict(capture.scene_info)
    info["pileup"] = {"correction": "coates", "pulses": int(pulses),
                      "largest_detection_probability": float(most / pulses)}
    return capture.replace(H=H, scene_info=info)


def piled_up_counts(expected: np.ndarray, pulses: int, rng: np.random.Generator) -> np.ndarray:
    """First-photon counts of ``pulses`` pulses per histogram (int64, ``expected``'s shape,
    time on axis 0), drawn for the mean photon counts ``expected`` an ideal detector would
    see over those pulses: one multinomial draw per histogram over its bins and 'none'."""
    mean = np.asarray(expected, dtype=np.float64)
    p = np.moveaxis(first_photon_probabilities(mean / pulses), 0, -1)
    none = np.clip(1.0 - p.sum(axis=-1, keepdims=True), 0.0, 1.0)
    draws = rng.multinomial(int(pulses), np.concatenate([p, none], axis=-1))
    return np.moveaxis(draws[..., :-1], -1, 0).astype(np.int64)

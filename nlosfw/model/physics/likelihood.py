"""The likelihood ``rsd_prior`` fits by: plain least squares, the Poisson noise of the
capture's photon counts to second order (``likelihood: poisson``, here), or the exact
Poisson likelihood of the counts in every time bin (``likelihood: poisson_counts``,
:mod:`nlosfw.model.physics.counts`).

A phasor sample is a DFT of a wall point's histogram, P(x, f) = sum_t K(f, t) n(x, t). With
Poisson counts n its variance is Var P(x, f) = sum_t |K(f, t)|^2 n(x, t): for every nlosfw
transform delta_t^2 times the point's count (:mod:`nlosfw.evaluation.noise_floor`), so
points that caught many photons (bright, near the laser, late ambient light) are noisier.
Each sample sums hundreds of bins, so by the central limit theorem its noise is Gaussian
with that variance, and the negative log-likelihood of the transient counts, seen through
the band, is the weighted least squares

    1/2 sum_{f, x} |A_f a - P_f|^2 (x) / sigma^2(x),

sigma^2(x) the mean of Var P(x, f) over the band (the same at every frequency for a DFT).
It is the Poisson likelihood to second order, not the exact one of the counts of each
time bin (that needs a forward model of the whole spectrum: ``poisson_counts``). The fit
runs on the whitened operator W^(1/2) A, its columns normalised
by their weighted norms. Weights are relative (their mean over the kept points is 1), and a
variance is taken as at least ``_FLOOR`` of the median, so that a point with no counts
is not weighted without bound. The field must carry its variance
(:attr:`~nlosfw.transform.field.PhasorField.variance`): the pipeline gives it for
captures of photon counts.
"""

from __future__ import annotations

import numpy as np

from nlosfw.common.config import Choice
from nlosfw.common.errors import ConfigError
from nlosfw.model.physics.wall import WallSamples
from nlosfw.transform.field import PhasorField

#: The smallest variance, as a fraction of the kept points' median.
_FLOOR = 0.01


class Likelihood(Choice):
    """What ``rsd_prior``'s data term is (see the module docstring)."""

    least_squares = "least_squares"
    poisson = "poisson"
    poisson_counts = "poisson_counts"


def sample_weights(field: PhasorField, samples: WallSamples, who: str = "rsd_prior"
                   ) -> np.ndarray:
    """The square roots of the weights 1 / sigma^2(x) (mean weight 1 over the kept points)
    on the canonical wall grid of ``samples`` (ny, nx), zero where not sampled; a
    ConfigError for ``model.likelihood`` naming ``who`` when ``field`` has no variance."""
    if field.variance is None:
        raise ConfigError("model.likelihood", f"{who}: poisson weighs the samples by their "
                          "Poisson variance, which this field does not carry: it needs a "
                          "capture of photon counts run through the pipeline (or a "
                          "PhasorField with variance); use least_squares")
    per_point = samples.on_grid(field.variance.mean(axis=0))            # (ny, nx)
    kept = np.ones(per_point.shape, bool) if samples.mask is None else samples.mask
    median = float(np.median(per_point[kept]))
    if not median > 0:
        raise ConfigError("model.likelihood", f"{who}: poisson needs photon counts at the "
                          "kept wall points, but most of them caught none; use least_squares")
    variance = np.maximum(per_point, _FLOOR * median)
    weights = np.where(kept, 1.0 / variance, 0.0)
    weights /= weights[kept].mean()
    return np.sqrt(weights)


def weight_summary(sqrt_weights: np.ndarray, mask: np.ndarray | None) -> dict[str, float]:
    """The fit report's account of the weights (mean 1 over the kept points): the smallest
    and the largest, how uneven the capture's noise was over the wall."""
    kept = sqrt_weights[mask] if mask is not None else sqrt_weights.ravel()
    weights = kept.astype(np.float64) ** 2
    return {"poisson_weight_min": float(weights.min()), "poisson_weight_max": float(weights.max())}

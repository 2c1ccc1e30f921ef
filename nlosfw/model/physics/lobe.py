"""The glossy lobe of ``rsd_prior``'s voxels (``lobe.fit``): its exponent fitted jointly
with the albedo.

A voxel's surface may reflect more towards its normal than a Lambertian one: the
simulators' lobe multiplies its BRDF by cos^k of the half vector's angle
(:mod:`nlosfw.simulate.physics`), which for a confocal scan of a surface facing the wall
is cos^k of the angle at which a wall point sees it. The albedo, the same for every wall
point, cannot take that falloff over the wall up, so k is identifiable from the kept
samples. It is chosen by predictive error, not by the training residual: a tenth of the
kept wall points (drawn with ``seed``) is held out, the albedo is fitted on the rest (a
quarter of the iterations) for each k tried, and k is the one whose field is closest to
the held-out points, ||A_val a - P_val|| / ||P_val|| (less each frequency's mean over them
with ``background: constant``); a bounded scalar search over [0, ``lobe.max``] to
``lobe.tolerance``, the Lambertian k = 0 tried too (the search never evaluates its
bounds). The full fit then uses every kept point.

Why not the training residual: on the shared measured captures it keeps falling as k goes
below 0 while the held-out excess error rises: a lobe that brightens oblique points fits
noise there (``studies/physics_terms_measured/README.md``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from nlosfw.common.errors import FitError
from nlosfw.model.physics.background import Background
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.model.physics.operator import SceneOperator
from nlosfw.model.physics.wall import validation_split

log = logging.getLogger(__name__)

#: Evaluations of the bounded search at most (each one fits the albedo again).
_MAX_EVALUATIONS = 12
#: The fraction of the kept wall points held out to choose k.
_VALIDATION_FRACTION = 0.1


def fit_lobe(config: RSDPriorConfig, operator: Callable[[float, np.ndarray], SceneOperator],
             solve: Callable[[SceneOperator, np.ndarray, int], np.ndarray], data: np.ndarray,
             kept: np.ndarray | None) -> float:
    """The lobe exponent k of the module docstring. ``operator(k, mask)``: the operator
    with lobe k onto the wall points of ``mask``; ``solve(op, data, iterations)``: the
    albedo; ``data`` (F, ny, nx) the training field on the wall grid, ``kept`` (ny, nx) its
    sampled points (None: all)."""
    shape = data.shape[1:]
    train, validation = validation_split(shape, _VALIDATION_FRACTION, config.seed, kept)
    if validation is None:
        raise FitError("rsd_prior: lobe.fit holds out a tenth of the kept wall points and "
                       f"needs at least 10 of them, got {int(train.sum())}")
    fit_on, held = train > 0, validation > 0
    target = data * held
    iterations = max(1, config.iterations // 4)

    def error(k: float) -> float:
        albedo = solve(operator(k, fit_on), data * fit_on, iterations)
        miss = operator(k, held).forward(albedo) - target
        # with background: constant, the fit's offsets span every kept point (zero data at
        # the held ones); the held points' error is taken net of their own offset
        if config.background != Background.none:
            miss = miss - held * (miss.sum(axis=(1, 2), keepdims=True) / held.sum())
        return float(np.linalg.norm(miss) / np.linalg.norm(target))

    return search_lobe(error, config)


def search_lobe(residual: Callable[[float], float], config: RSDPriorConfig) -> float:
    """The exponent k in [0, ``lobe.max``] with the least ``residual(k)`` (an error) to
    ``lobe.tolerance`` (see the module docstring); each k is evaluated once."""
    tried: dict[float, float] = {}

    def once(k: float) -> float:
        k = float(k)
        if k not in tried:
            tried[k] = residual(k)
            log.debug("rsd_prior: lobe %.3f: relative error %.6f", k, tried[k])
        return tried[k]

    from scipy.optimize import minimize_scalar  # not at import: the config alone is light

    once(0.0)
    minimize_scalar(once, bounds=(0.0, config.lobe.max), method="bounded",
                    options={"xatol": config.lobe.tolerance, "maxiter": _MAX_EVALUATIONS})
    best = min(tried, key=lambda k: tried[k])
    log.info("rsd_prior: lobe exponent %.3f (%d values tried)", best, len(tried))
    return best

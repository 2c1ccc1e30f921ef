"""``likelihood: poisson_counts``: ``rsd_prior``'s albedo fitted by the exact Poisson
likelihood of the photon counts in every time bin, beside the least-squares phasor loss.

Model. The expected count at a kept wall point x in time bin j is

    lambda_j(x) = c sum_v a_v s(x, v) m_j(p(x, v)) + b_j,

s the scene operator's amplitude of the voxel's legs (:func:`leg_amplitude`, the lobe
included), p its path (plus the device legs when the capture's times include them),
m_j(p) the share of the system's pulse centred at p + tau that falls in bin j (a Gaussian
of standard deviation sigma from the fitted response; with none, all of it in the bin
holding p), c = scale * count_scale / delta_t the photons per unit of the model's albedo,
and b_j >= 0 a background per bin, the same over the wall (ambient light, dark counts).
The temporal DFT of lambda without b is the model's phasor field, the response's gains
included (``tests/model/physics/test_counts.py`` checks it against the FFT scene operator): this is
the time-domain forward model of the whole spectrum that the phasor fit does not have.

Fit. Maximise L = sum n log lambda - lambda over the kept points and every bin from the
first that holds a count (a gate's zeros are not measurements), on bins ``counts.bin``
wide: sums of whole bins of the capture, so still Poisson counts. EM (Richardson-Lucy for
the albedo, the same for the background) keeps both >= 0 and never lowers L:

    a_v <- a_v (M^T (n / lambda))_v / (M^T 1)_v,    b_j <- b_j mean_x (n / lambda)_j(x).

It starts from the least-squares fit, whose L1 penalty chose the voxels: a multiplicative
update keeps the zeros of its start, so the counts refine the albedo on that support
(which keeps M, one row per point and bin, to the support's columns).

When to stop. Run to convergence, EM fits the counts' noise (Richardson-Lucy's known
semi-convergence; on the shared captures: ``studies/physics_terms_measured/README.md``).
So by default (``counts.stop``) the counts are split once more, binomially, into two
independent halves: EM runs on one, and stops at the iteration where the other's
likelihood peaks (:func:`stopping_iteration`); the fit on all the counts then runs that
many iterations.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.special import ndtr

from nlosfw.capture.geometry import CaptureGeometry, CaptureKind
from nlosfw.common.config import Choice
from nlosfw.common.errors import ConfigError, FitError
from nlosfw.model.physics.background import WallBackground
from nlosfw.model.physics.operator import OperatorOptions, VoxelLattice, leg_amplitude
from nlosfw.model.physics.response import SystemResponse
from nlosfw.transform.counts import BinnedCounts, bin_counts
from nlosfw.transform.field import PhasorField

if TYPE_CHECKING:
    from nlosfw.model.physics.config import RSDPriorConfig

#: The pulse is cut this many standard deviations either side of its centre.
_TAIL = 4.0
#: Entries of the sparse operator built at once (bounds the building's memory).
_BLOCK = 2**22


class CountsStop(Choice):
    """When the counts' EM stops (module docstring)."""

    likelihood = "likelihood"
    none = "none"


@dataclass(frozen=True, eq=False)
class CountsScene:
    """The least-squares fit the counts' model is made of."""

    lattice: VoxelLattice
    geometry: CaptureGeometry
    options: OperatorOptions
    """The scene operator's amplitude and lobe."""
    response: SystemResponse | None
    scale: float
    """The field's units per unit of the model's albedo."""


@dataclass(frozen=True, eq=False)
class CountsFit:
    """What the counts' fit gives: the albedo, the background and its account."""

    albedo: np.ndarray
    """(Z, Y, X) on the lattice, in the model's units (zero off the start's support)."""
    background: WallBackground
    """The background's phasor (raw field units)."""
    log_likelihood: np.ndarray
    """L (without the constant sum log n!) before each iteration and after the last."""
    summary: dict[str, float]
    """The fit report's values (``counts_*``)."""


def counts_operator(problem: BinnedCounts, scene: CountsScene, support: np.ndarray,
                    photons_per_unit: float) -> sparse.csr_matrix:
    """M: expected photons per fitted bin and point (row j * N + x) per unit of albedo of
    each voxel of ``support`` (flat lattice indices; column order), without background."""
    geometry, options, response = scene.geometry, scene.options, scene.response
    vox = scene.lattice.points().reshape(-1, 3)[support]
    pts = problem.points
    n_points, width = pts.shape[0], float(problem.edges[1] - problem.edges[0])
    sigma = 0.0 if response is None else float(response.sigma)
    shift = 0.0 if response is None else float(response.tau)
    taps = np.arange(-math.ceil(_TAIL * sigma / width), math.ceil(_TAIL * sigma / width) + 1)
    legs = geometry.device_path(pts)
    confocal = geometry.kind is CaptureKind.CONFOCAL
    rows, cols, vals = [], [], []
    block = max(1, _BLOCK // max(1, n_points * taps.size))
    for start in range(0, vox.shape[0], block):
        v = vox[start:start + block]
        r_s = np.sqrt(((v[:, None, :] - pts[None, :, :]) ** 2).sum(-1))     # (n, N)
        g_s = leg_amplitude(r_s, v[:, 2:3], options.amplitude, options.lobe)
        if confocal:
            path, amp = 2 * r_s, g_s**2
        else:
            laser = np.asarray(geometry.laser_point, dtype=float)
            r_l = np.linalg.norm(v - laser, axis=-1)[:, None]
            path = r_l + r_s
            amp = leg_amplitude(r_l, v[:, 2:3], options.amplitude, options.lobe) * g_s
        centre = path + legs[None, :] + shift
        home = np.floor((centre - problem.edges[0]) / width).astype(np.int64)
        for tap in taps:
            j = home + tap
            if sigma > 0:
                lo = problem.edges[0] + j * width
                share = ndtr((lo + width - centre) / sigma) - ndtr((lo - centre) / sigma)
            else:
                share = np.ones_like(centre)
            ok = (j >= 0) & (j < problem.counts.shape[0]) & (share > 0)
            col, pt = np.nonzero(ok)
            rows.append(j[ok] * n_points + pt)
            cols.append(col + start)
            vals.append(photons_per_unit * amp[ok] * share[ok])
    shape = (problem.counts.size, int(support.size))
    if not rows:
        return sparse.csr_matrix(shape)
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))), shape=shape)


def log_likelihood(counts: np.ndarray, expected: np.ndarray) -> float:
    """sum n log lambda - lambda (without sum log n!)."""
    return float(np.sum(counts * np.log(expected)) - np.sum(expected))


def fit_counts(n: np.ndarray, operator: sparse.csr_matrix, start: np.ndarray,
               iterations: int, score: Callable[[np.ndarray], float] | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """EM on the counts ``n`` (J, N) from the albedo ``start`` (support,) (module
    docstring): (albedo, background per fitted bin (J,), the score of the expected counts
    before each iteration and after the last). The score is the log-likelihood of ``n``
    unless ``score`` (of the expected counts (J, N)) is given."""
    score = score or (lambda expected: log_likelihood(n, expected))
    a = np.asarray(start, dtype=np.float64).copy()
    scene = (operator @ a).reshape(n.shape)
    excess = n.mean(axis=1) - scene.mean(axis=1)
    b = np.maximum(excess, 0.05 * n.mean(axis=1)) + 1e-6 * max(float(n.mean()), 1e-12)
    colsum = np.asarray(operator.sum(axis=0)).ravel()
    seen = colsum > 0
    history = [score(scene + b[:, None])]
    for _ in range(iterations):
        ratio = n / (scene + b[:, None])
        a[seen] *= (operator.T @ ratio.ravel())[seen] / colsum[seen]
        b *= ratio.mean(axis=1)
        scene = (operator @ a).reshape(n.shape)
        history.append(score(scene + b[:, None]))
    return a, b, np.asarray(history)


def stopping_iteration(problem: BinnedCounts, operator: sparse.csr_matrix, start: np.ndarray,
                       iterations: int, seed: int) -> int:
    """The iterations of EM that fit the counts best without fitting their noise: split
    every count into Binomial(n, 1/2) and the rest (two independent Poisson halves, as
    count splitting does), run EM on one half from half the ``start`` and return the
    iteration at which the other half's likelihood peaks (at least one)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC0DE]))
    counts = problem.counts
    half = rng.binomial(counts.astype(np.int64), 0.5).astype(np.float64)
    other = counts - half
    history = fit_counts(half, operator, 0.5 * np.asarray(start), iterations,
                         lambda expected: log_likelihood(other, expected))[2]
    return max(1, int(np.argmax(history)))


def refine_by_counts(field: PhasorField, scene: CountsScene, albedo: np.ndarray,
                     config: RSDPriorConfig) -> CountsFit:
    """The least-squares ``albedo`` (Z, Y, X) refined by EM on the counts of the training
    ``field``'s points (``config``'s ``counts`` options: ``counts.iterations`` of EM, or
    with ``counts.stop`` as many as :func:`stopping_iteration` finds, up to that); the
    background's phasor at the field's frequencies."""
    iterations, stop, seed = config.counts.iterations, config.counts.stop, config.seed
    counts = field.counts
    if counts is None:
        raise ConfigError("model.likelihood", "rsd_prior: poisson_counts fits the photon "
                          "counts, which this field does not carry: it needs a capture of "
                          "photon counts run through the pipeline with split.spectral=none "
                          "(or a PhasorField with counts); use least_squares or poisson")
    bin_width = config.counts.bin or 0.25 / float(field.frequencies.max())
    problem = bin_counts(counts, field.wall_xyz, bin_width)
    flat = np.asarray(albedo, dtype=np.float64).ravel()
    support = np.flatnonzero(flat > 0)
    if support.size == 0:
        raise FitError("poisson_counts: the least-squares albedo it starts from is zero")
    photons = scene.scale * counts.count_scale / counts.delta_t
    operator = counts_operator(problem, scene, support, photons)
    steps = iterations if stop == CountsStop.none else stopping_iteration(
        problem, operator, flat[support], iterations, seed)
    a, b, history = fit_counts(problem.counts, operator, flat[support], steps)
    out = np.zeros_like(flat)
    out[support] = a
    total = float(problem.counts.sum())
    summary = {"counts_iterations": float(steps),
               "counts_bin_mm": 1e3 * problem.factor * counts.delta_t,
               "counts_support_voxels": float(support.size),
               "counts_background": float(np.median(b) / problem.factor),
               "counts_loglik_gain": float((history[-1] - history[0]) / max(total, 1.0))}
    return CountsFit(out.reshape(np.shape(albedo)),
                     WallBackground(field.frequencies, problem.field_of(b, field.frequencies)),
                     history, summary)

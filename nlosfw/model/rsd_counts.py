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
included (``tests/test_rsd_counts.py`` checks it against the FFT scene operator): this is
the time-domain forward model of the whole spectrum that the phasor fit does not have.

Fit. Maximise L = sum n log lambda - lambda over the kept points and the bins the
lattice's paths reach (from the first bin holding any count: a gate's zeros are not
measurements), on bins ``counts_bin`` wide: sums of whole bins of the capture, so still
Poisson counts. EM (Richardson-Lucy for the albedo, the same for the background) keeps
both >= 0 and never lowers L:

    a_v <- a_v (M^T (n / lambda))_v / (M^T 1)_v,    b_j <- b_j mean_x (n / lambda)_j(x).

It starts from the least-squares fit, whose L1 penalty chose the voxels: a multiplicative
update keeps the zeros of its start, so the counts refine the albedo on that support
(which keeps M, one row per point and bin, to the support's columns).

When to stop. Run to convergence, EM fits the counts' noise (Richardson-Lucy's known
semi-convergence): on the shared diffuse S at 16x the held-out excess was -7.4 dB after
10 iterations and -3.5 dB after 50 (least squares alone: -4.6 dB). So by default
(``counts_stop``) the counts are split once more, binomially, into two independent halves:
EM runs on one, and stops at the iteration where the other's likelihood peaks
(:func:`stopping_iteration`); the fit on all the counts then runs that many iterations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.special import ndtr

from nlosfw.capture.geometry import CaptureGeometry, CaptureKind
from nlosfw.common.errors import ConfigError, FitError
from nlosfw.model.rsd_background import WallBackground
from nlosfw.model.rsd_response import SystemResponse
from nlosfw.model.scene_operator import OperatorOptions, VoxelLattice, leg_amplitude
from nlosfw.transform.field import PhasorField, PhotonCounts
from nlosfw.transform.temporal_dft import unit_phasor

#: The pulse is cut this many standard deviations either side of its centre.
_TAIL = 4.0
#: Entries of the sparse operator built at once (bounds the building's memory).
_BLOCK = 2**22


@dataclass(frozen=True)
class CountsProblem:
    """The counts of the kept wall points binned for the fit, and where they lie."""

    counts: np.ndarray
    """(J, N) photons per fitted bin J and kept point N."""
    edges: np.ndarray
    """(J + 1,) bin edges in metres of path."""
    points: np.ndarray
    """(N, 3) the kept wall points."""
    factor: int
    """Bins of the capture summed into one fitted bin."""


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


def counts_problem(counts: PhotonCounts, wall_xyz: np.ndarray, bin_width: float
                   ) -> CountsProblem:
    """The kept points' counts summed into bins of the largest whole number of the
    capture's bins not wider than ``bin_width`` (m), from the first bin holding a count."""
    n_raw = counts.counts.reshape(counts.counts.shape[0], -1)
    points = np.asarray(wall_xyz, dtype=float).reshape(-1, 3)
    if n_raw.shape[1] != points.shape[0]:
        raise FitError(f"counts of {n_raw.shape[1]} wall points for {points.shape[0]} points")
    factor = max(1, int(math.floor(bin_width / counts.delta_t + 1e-9)))
    hits = np.flatnonzero(n_raw.sum(axis=1) > 0)
    if hits.size == 0:
        raise FitError("poisson_counts: the kept wall points caught no photon")
    first = int(hits[0])
    n_bins = (n_raw.shape[0] - first) // factor
    if n_bins < 1:
        raise FitError("poisson_counts: fewer time bins after the first count than one "
                       "fitted bin holds; lower counts_bin")
    binned = n_raw[first:first + n_bins * factor].reshape(n_bins, factor, -1).sum(axis=1)
    width = factor * counts.delta_t
    edges = counts.t_start + first * counts.delta_t + width * np.arange(n_bins + 1)
    return CountsProblem(binned, edges, points, factor)


def counts_operator(problem: CountsProblem, scene: CountsScene, support: np.ndarray,
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


def fit_counts(counts: np.ndarray, operator: sparse.csr_matrix, start: np.ndarray,
               iterations: int, check: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """EM on ``counts`` (J, N) from the albedo ``start`` (support,) (module docstring):
    (albedo, background per fitted bin (J,), the log-likelihood before each iteration and
    after the last). With ``check`` (counts of the same shape, independent of ``counts``),
    the log-likelihood is of ``check`` instead, under the fitted expectation (the
    validation that chooses when to stop)."""
    n = counts
    n_bins, n_points = n.shape
    a = np.asarray(start, dtype=np.float64).copy()
    scene = (operator @ a).reshape(n_bins, n_points)
    excess = n.mean(axis=1) - scene.mean(axis=1)
    b = np.maximum(excess, 0.05 * n.mean(axis=1)) + 1e-6 * max(float(n.mean()), 1e-12)
    colsum = np.asarray(operator.sum(axis=0)).ravel()
    seen = colsum > 0
    history = []
    for _ in range(iterations + 1):
        expected = scene + b[:, None]
        history.append(log_likelihood(n if check is None else check, expected))
        if len(history) > iterations:
            break
        ratio = n / expected
        a[seen] *= (operator.T @ ratio.ravel())[seen] / colsum[seen]
        b *= ratio.mean(axis=1)
        scene = (operator @ a).reshape(n_bins, n_points)
    return a, b, np.asarray(history)


def stopping_iteration(counts: np.ndarray, operator: sparse.csr_matrix, start: np.ndarray,
                       iterations: int, seed: int) -> int:
    """The iterations of EM that fit the counts best without fitting their noise: split
    every count into Binomial(n, 1/2) and the rest (two independent Poisson halves, as
    count splitting does), run EM on one half from half the ``start`` and return the
    iteration at which the other half's likelihood peaks (at least 1)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xC0DE]))
    half = rng.binomial(counts.astype(np.int64), 0.5).astype(np.float64)
    history = fit_counts(half, operator, 0.5 * np.asarray(start), iterations,
                         check=counts - half)[2]
    return max(1, int(np.argmax(history)))


def background_field(problem: CountsProblem, background: np.ndarray, counts: PhotonCounts,
                     frequencies: np.ndarray) -> WallBackground:
    """The background's phasor (raw field units, the same at every wall point): each fitted
    bin's photons spread evenly over its capture bins, through the temporal DFT."""
    k = problem.factor
    per_bin = np.repeat(background / k, k)                    # photons per capture bin
    step = counts.delta_t
    centres = problem.edges[0] + (np.arange(per_bin.size) + 0.5) * step
    f = np.asarray(frequencies, dtype=float)
    values = unit_phasor(-np.outer(f, centres)) @ per_bin * step / counts.count_scale
    return WallBackground(f, np.asarray(values, dtype=np.complex128))


def refine_by_counts(field: PhasorField, scene: CountsScene, albedo: np.ndarray,
                     iterations: int, bin_width: float, seed: int | None) -> CountsFit:
    """The least-squares ``albedo`` (Z, Y, X) refined by EM on the counts of the training
    ``field``'s points, in bins about ``bin_width`` wide (m): ``iterations`` of it, or with
    a ``seed`` as many as :func:`stopping_iteration` finds, up to ``iterations``; the
    background's phasor at the field's frequencies."""
    counts = field.counts
    if counts is None:
        raise ConfigError("model.likelihood", "rsd_prior: poisson_counts fits the photon "
                          "counts, which this field does not carry: it needs a capture of "
                          "photon counts run through the pipeline with split.spectral=none "
                          "(or a PhasorField with counts); use least_squares or poisson")
    problem = counts_problem(counts, field.wall_xyz, bin_width)
    flat = np.asarray(albedo, dtype=np.float64).ravel()
    support = np.flatnonzero(flat > 0)
    if support.size == 0:
        raise FitError("poisson_counts: the least-squares albedo it starts from is zero")
    photons = scene.scale * counts.count_scale / counts.delta_t
    operator = counts_operator(problem, scene, support, photons)
    steps = iterations if seed is None else stopping_iteration(
        problem.counts, operator, flat[support], iterations, seed)
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
                     background_field(problem, b, counts, field.frequencies), history, summary)

"""Stacking field models on held-out wall points: which of the kept points validate, the
members' fields there, and the convex weights that predict them best.

The ensemble (:mod:`nlosfw.model.hybrid.ensemble`) holds out a fraction of the kept wall
points (every frequency of each), fits its members on the rest and weighs them by their
error at the held-out points: the weights w >= 0, sum w = 1, minimising

    sum_{f, held-out points} | sum_k w_k F_k - P |^2

(Breiman's stacked regression with the weights constrained to the simplex; solved
exactly by trying every support of the weights, :func:`simplex_weights`). Since the
points held out are measured with the same noise as the rest and the members never saw
them, the difference of two members' errors there estimates the difference of their errors
against the noise-free field at wall points they have not seen, which is what a sparse
scan asks of a field model.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.image.plane_convolution import GridLayout, from_canonical
from nlosfw.model.interface import FieldModel
from nlosfw.model.physics.wall import WallSamples, validation_split, wall_samples
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True, eq=False)
class HeldOutPoints:
    """The kept wall points split into the points members train on and the validation
    points that weigh them: ``validation`` (Y, X) over the field's own wall layout (True:
    held out), from :func:`validation_split` on the samples' canonical grid (so a model that
    calls that function with the same fraction and seed holds out the same points)."""

    validation: np.ndarray
    samples: WallSamples
    canonical: np.ndarray
    """The same points on the samples' canonical grid (ny, nx), True where held out."""

    @property
    def count(self) -> int:
        """How many points are held out."""
        return int(self.validation.sum())

    def measured(self, field: PhasorField) -> np.ndarray:
        """The values of ``field`` at the held-out points (F, N), in canonical order."""
        return self.samples.on_grid(field.values)[:, self.canonical]

    def on_grid(self, model: FieldModel, frequencies: np.ndarray) -> np.ndarray:
        """``model``'s field on the samples' whole canonical grid (F, ny, nx): a regular
        grid, where a physical model predicts by FFT."""
        return model.predict(canonical_wall(self.samples.layout), frequencies)

    def in_field_layout(self, on_grid: np.ndarray) -> np.ndarray:
        """An array (..., ny, nx) on the canonical grid at the field's own samples, laid
        out as the field's values (..., Y, X)."""
        cells = self.samples.cells
        if cells is None:
            return from_canonical(on_grid, self.samples.layout.order,
                                  axes=(on_grid.ndim - 2, on_grid.ndim - 1))
        return on_grid[..., cells[0], cells[1]][..., None, :]


def canonical_wall(layout: GridLayout) -> np.ndarray:
    """(x, y) of every point of ``layout``'s canonical grid, (ny, nx, 2)."""
    (y0, x0), (dy, dx), (ny, nx) = layout.origin, layout.spacing, layout.shape
    y, x = np.meshgrid(y0 + dy * np.arange(ny), x0 + dx * np.arange(nx), indexing="ij")
    return np.stack([x, y], axis=-1)


def held_out_points(field: PhasorField, fraction: float, seed: int, who: str
                    ) -> HeldOutPoints:
    """``fraction`` of the kept wall points of ``field`` (a grid, or scattered points of
    one), drawn with ``seed`` as :func:`~nlosfw.model.physics.wall.validation_split` draws
    them on the samples' canonical grid; a DataError naming ``who`` when none would be
    held out (fewer than 10 kept points, or a fraction too small)."""
    samples = wall_samples(field, who)
    _, chosen = validation_split(samples.layout.shape, fraction, seed, samples.mask)
    if chosen is None:
        raise DataError(f"{who}: {samples.count} kept wall points hold out none at "
                        f"validation fraction {fraction}; it needs 10 or more kept points "
                        "and at least one held out to weigh its members")
    ny, nx = field.grid_shape
    index = np.arange(1, ny * nx + 1).reshape(ny, nx)     # 1-based: 0 is "not sampled"
    on_grid = samples.on_grid(index)
    picked = on_grid[chosen.astype(bool)] - 1
    validation = np.zeros(ny * nx, dtype=bool)
    validation[picked] = True
    return HeldOutPoints(validation.reshape(ny, nx), samples, chosen.astype(bool))


def subset_field(field: PhasorField, mask: np.ndarray) -> PhasorField:
    """The wall points of ``field`` where ``mask`` (its wall layout, (Y, X)) is True, as
    scattered points (one row: wall (1, N, 3), values (F, 1, N)), their variance and photon
    counts with them."""
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != field.grid_shape:
        raise DataError(f"subset_field: mask of shape {mask.shape} for a field on a "
                        f"{field.grid_shape} wall layout")
    var, counts = field.variance, field.counts
    picked_counts = None if counts is None else dataclasses.replace(
        counts, counts=counts.counts[:, mask][:, None, :])
    return field.replace(values=field.values[:, mask][:, None, :],
                         wall_xyz=field.wall_xyz[mask][None],
                         variance=None if var is None else var[:, mask][:, None, :],
                         counts=picked_counts)


def simplex_weights(gram: np.ndarray, target: np.ndarray) -> np.ndarray:
    """w >= 0 with sum w = 1 minimising w' G w - 2 b' w (``gram`` G (K, K), symmetric
    positive semi-definite; ``target`` b (K,)): the exact minimiser, found by solving the
    equality-constrained problem on every support and keeping the best feasible one
    (K is small: 2^K - 1 supports). Ties go to the smaller support, then the earlier
    members."""
    g = np.asarray(gram, dtype=np.float64)
    b = np.asarray(target, dtype=np.float64)
    k = b.size
    if g.shape != (k, k) or k < 1:
        raise DataError(f"simplex_weights: gram {g.shape} and target {b.shape} do not match")
    scale = float(np.max(np.abs(np.diag(g)))) or 1.0
    best, best_value = None, np.inf
    for size in range(1, k + 1):
        for support in itertools.combinations(range(k), size):
            w = _on_support(g, b, list(support))
            if w is None:
                continue
            value = float(w @ g @ w - 2 * b @ w)
            # strictly better by more than rounding: ties keep the smaller support
            if value < best_value - 1e-12 * scale:
                best, best_value = w, value
    if best is None:                        # unreachable: every vertex is feasible
        raise DataError("simplex_weights: no feasible weights")
    return best


def _on_support(g: np.ndarray, b: np.ndarray, support: list[int]) -> np.ndarray | None:
    """The minimiser with weights only on ``support`` summing to 1, or None when it has a
    negative weight (it then lies on a smaller support)."""
    n = len(support)
    w = np.zeros(b.size)
    if n == 1:
        w[support[0]] = 1.0
        return w
    kkt = np.zeros((n + 1, n + 1))
    kkt[:n, :n] = g[np.ix_(support, support)]
    kkt[:n, n] = kkt[n, :n] = 1.0
    rhs = np.concatenate([b[support], [1.0]])
    solution = np.linalg.lstsq(kkt, rhs, rcond=None)[0][:n]
    if np.any(solution < 0) or not np.all(np.isfinite(solution)):
        return None
    w[support] = solution / solution.sum()
    return w


def stacking_problem(predictions: np.ndarray, measured: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, float]:
    """(G, b, c) of the squared error |sum_k w_k F_k - P|^2 = w' G w - 2 b' w + c of member
    fields ``predictions`` (K, ...) against ``measured`` (...), complex: G_kl = Re <F_k, F_l>,
    b_k = Re <F_k, P>, c = ||P||^2."""
    f = np.asarray(predictions).reshape(predictions.shape[0], -1)
    p = np.asarray(measured).reshape(-1)
    gram = np.real(f.conj() @ f.T)
    target = np.real(f.conj() @ p)
    return gram, target, float(np.real(np.vdot(p, p)))

"""Non-negative sparse least squares by monotone FISTA (Beck & Teboulle 2009).

Minimises, over real x >= 0 (any shape),

    F(x) = 1/2 ||A x - b||^2 + l1 sum(x) + tv TV_eps(x)

for a complex linear operator A given as ``forward`` (x -> A x) and ``adjoint``
(P -> A^H P, complex). The gradient of the data term is Re(A^H (A x - b)); on x >= 0 the
L1 norm is sum(x), so its proximal step with the projection is max(x - t l1, 0).
TV_eps(x) = sum sqrt(|grad x|^2 + eps^2) - eps is a smoothed isotropic total variation
(forward differences along the chosen axes; its gradient is (4 n_axes / eps)-Lipschitz),
handled with the smooth part. The monotone variant keeps the best iterate, so F never increases;
A of every iterate is tracked by linearity, so each iteration costs one ``forward`` and
one ``adjoint``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

Operator = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class FistaProblem:
    """The operator, the data and the weights of the problem."""

    forward: Operator
    adjoint: Operator
    data: np.ndarray
    shape: tuple[int, ...]
    l1: float = 0.0
    tv: float = 0.0
    tv_eps: float = 1e-3
    tv_axes: tuple[int, ...] = ()
    """Axes of the total variation (empty: every axis)."""


@dataclass
class FistaResult:
    """The solution and how it was reached."""

    x: np.ndarray
    objective: list[float] = field(default_factory=list)
    """F of the kept iterate after each iteration (non-increasing)."""
    residual: float = 0.0
    """||A x - b|| / ||b|| at the end."""
    iterations: int = 0


def lipschitz(forward: Operator, adjoint: Operator, shape: tuple[int, ...],
              iterations: int = 20, seed: int = 0) -> float:
    """Largest eigenvalue of x -> Re(A^H A x) over real x, by power iteration from a
    random start drawn from ``seed`` (an estimate from below, tight after ~20 steps)."""
    x = np.random.default_rng(seed).random(shape)
    x /= np.linalg.norm(x)
    value = 0.0
    for _ in range(max(1, iterations)):
        y = adjoint(forward(x)).real
        value = float(np.linalg.norm(y))
        if value == 0.0:
            return 0.0
        x = y / value
    return value


def smoothed_tv(x: np.ndarray, eps: float,
                axes: tuple[int, ...] = ()) -> tuple[float, np.ndarray]:
    """(TV_eps(x), its gradient) with forward differences along ``axes`` (empty: all) and
    Neumann borders."""
    axes = axes or tuple(range(x.ndim))
    diffs = [np.diff(x, axis=k, append=np.take(x, [-1], axis=k)) for k in axes]
    norm = np.sqrt(sum(d * d for d in diffs) + eps * eps)
    value = float(np.sum(norm) - eps * x.size)
    grad = np.zeros_like(x)
    for k, d in zip(axes, diffs, strict=True):
        flux = d / norm
        # the adjoint of the forward difference (last difference is zero by the border)
        before = np.take(flux, range(0, x.shape[k] - 1), axis=k)
        shifted = np.concatenate([np.zeros_like(np.take(flux, [0], axis=k)), before], axis=k)
        last = np.concatenate([np.take(flux, range(0, x.shape[k] - 1), axis=k),
                               np.zeros_like(np.take(flux, [0], axis=k))], axis=k)
        grad += shifted - last
    return value, grad


def tv_lipschitz(n_axes: int, eps: float) -> float:
    """A Lipschitz constant of grad TV_eps over ``n_axes`` axes: ||grad||^2 / eps."""
    return 4.0 * n_axes / eps


def solve(problem: FistaProblem, step: float, iterations: int,
          on_iteration: Callable[[int, float, float], None] | None = None,
          tolerance: float = 0.0, start: np.ndarray | None = None) -> FistaResult:
    """Monotone FISTA from x = 0 (or a copy of ``start``, >= 0) with step ``step`` (at most
    1/L of the smooth part).

    ``on_iteration(k, objective, relative_residual)`` is called after every iteration.
    Stops early when the objective's relative decrease over 10 iterations is below
    ``tolerance`` (0: run every iteration).
    """
    b = problem.data
    norm_b = float(np.linalg.norm(b)) or 1.0
    x = np.zeros(problem.shape) if start is None else np.maximum(start, 0.0)
    ax = np.zeros_like(b) if start is None else problem.forward(x)
    y, ay = x, ax
    t = 1.0
    f_x = _objective(problem, x, ax)
    history: list[float] = []
    k = 0
    for k in range(1, iterations + 1):
        grad = problem.adjoint(ay - b).real
        if problem.tv > 0:
            grad += problem.tv * smoothed_tv(y, problem.tv_eps, problem.tv_axes)[1]
        z = np.maximum(y - step * (grad + problem.l1), 0.0)
        az = problem.forward(z)
        f_z = _objective(problem, z, az)
        if f_z <= f_x:
            x_new, ax_new, f_new = z, az, f_z
        else:
            x_new, ax_new, f_new = x, ax, f_x
        t_new = (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0
        a, c = t / t_new, (t - 1.0) / t_new
        y = x_new + a * (z - x_new) + c * (x_new - x)
        ay = ax_new + a * (az - ax_new) + c * (ax_new - ax)
        x, ax, f_x, t = x_new, ax_new, f_new, t_new
        history.append(f_x)
        residual = float(np.linalg.norm(ax - b)) / norm_b
        if on_iteration is not None:
            on_iteration(k, f_x, residual)
        if tolerance > 0 and k > 10 and history[-11] - f_x <= tolerance * abs(history[-11]):
            break
    return FistaResult(x=x, objective=history, residual=float(np.linalg.norm(ax - b)) / norm_b,
                       iterations=k)


def _objective(problem: FistaProblem, x: np.ndarray, ax: np.ndarray) -> float:
    r = ax - problem.data
    value = 0.5 * float(np.vdot(r, r).real) + problem.l1 * float(np.sum(x))
    if problem.tv > 0:
        value += problem.tv * smoothed_tv(x, problem.tv_eps, problem.tv_axes)[0]
    return value

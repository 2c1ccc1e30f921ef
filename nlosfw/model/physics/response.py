"""The system's temporal response and time-origin offset for ``rsd_prior``: a complex gain
per frequency that multiplies the whole modelled field.

Units: the field's frequencies f are in cycles per metre of path (the capture's time axis
is path length c t), so both parameters are fitted in metres of path and reported in
picoseconds (divided by c).

* ``response.temporal: gaussian``: Gaussian timing jitter of standard deviation sigma
  blurs every time profile; its transfer function is the real gain
  m_f = exp(-(2 pi f sigma)^2 / 2).
* ``response.time_offset: true``: the capture's time origin is off by tau: a histogram shifted tau
  *later* than the model's (its recorded times too large by tau, e.g. k bins later:
  tau = k delta_t) has the phase ramp exp(-2 pi i f tau), the temporal DFT's convention
  P_f = sum_t H(t) exp(-2 pi i f t) delta_t. A positive tau: the signal arrives late.

The model's field is g_f A_f a with g_f = m_f exp(-2 pi i f tau), the albedo a the same at
every frequency (its overall scale absorbs any real scale of the gains); the fit folds the
gains, scaled to unit RMS, into the operator (G A, adjoint A^H G^H; |A_f e_v| does not
depend on f, so the column normalisation is unchanged).

Estimation. With the albedo fixed, sigma and tau have an exact least-squares form

    min_{s > 0, sigma, tau} sum_f ||s g_f A_f a - P_f||^2
    = max (sum_f m_f Re(exp(2 pi i f tau) z_f))^2 / sum_f m_f^2 e_f,

z_f = <A_f a, P_f>, e_f = ||A_f a||^2 (the per-frequency gains z_f / e_f weighted by e_f;
tau by a grid over one period of the frequency spacing then a bounded search, sigma by a
bounded search: no phase unwrapping). But alternating it with the albedo stalls: the
albedo absorbs most of a shift by moving in depth and most of a blur by spreading over
planes, and what is left barely moves the least-squares values (a point scatterer late
and blurred keeps tau and sigma near 0 after three rounds).
So the least-squares values only start :func:`search_response`, which minimises the fit's
own objective over sigma and tau, the albedo fitted again (warm started, a quarter of the
iterations) for every value tried: ``response.rounds`` rounds of a parabola per term, the
steps halving.

What it recovers on simulated captures and finds on the shared ones:
``studies/physics_terms_measured/README.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.common.config import Choice

#: Grid of the time-offset search, in periods of the highest frequency.
_TAU_GRID = 16
#: The largest jitter searched: the gain at the highest frequency is exp(-_SIGMA_MAX^2 / 2).
_SIGMA_MAX = 3.0
#: Refinements of sigma and tau in turn, per round.
_PASSES = 2


class TemporalResponse(Choice):
    """The system temporal response of ``rsd_prior`` (see the module docstring)."""

    none = "none"
    gaussian = "gaussian"


@dataclass(frozen=True)
class SystemResponse:
    """Fitted gains g_f = exp(-(2 pi f sigma)^2 / 2) exp(-2 pi i f tau)."""

    sigma: float = 0.0
    """[m] Standard deviation of the Gaussian jitter, in metres of path (0: none)."""
    tau: float = 0.0
    """[m] Time-origin offset in metres of path (positive: the signal arrives late)."""
    gaussian: bool = False
    """Whether sigma was fitted (reported)."""
    offset: bool = False
    """Whether tau was fitted (reported)."""

    def gains(self, frequencies: np.ndarray, unit_rms: bool = False) -> np.ndarray:
        """g_f at ``frequencies`` (cycles per metre), complex (F,); ``unit_rms``: divided by
        their RMS (a real scale the albedo absorbs)."""
        f = np.asarray(frequencies, dtype=float)
        m = np.exp(-0.5 * (2 * np.pi * f * self.sigma) ** 2)
        if unit_rms:
            m = m / np.sqrt(np.mean(m * m))
        return m * np.exp(-2j * np.pi * f * self.tau)

    def summary(self) -> dict[str, float]:
        """The fitted values for the fit report, in picoseconds."""
        out: dict[str, float] = {}
        if self.gaussian:
            out["response_sigma_ps"] = self.sigma / SPEED_OF_LIGHT * 1e12
        if self.offset:
            out["time_offset_ps"] = self.tau / SPEED_OF_LIGHT * 1e12
        return out

    def to_dict(self) -> dict[str, float | bool]:
        """Plain values for a model file's header."""
        return {"sigma": self.sigma, "tau": self.tau, "gaussian": self.gaussian,
                "offset": self.offset}

    @classmethod
    def from_dict(cls, values: dict[str, object]) -> SystemResponse:
        """The inverse of :meth:`to_dict` (TypeError/KeyError/ValueError on bad values)."""
        sigma, tau = float(str(values["sigma"])), float(str(values["tau"]))
        if not (math.isfinite(sigma) and math.isfinite(tau) and sigma >= 0):
            raise ValueError("sigma and tau must be finite, sigma >= 0")
        return cls(sigma, tau, bool(values["gaussian"]), bool(values["offset"]))


def estimate_response(model: np.ndarray, data: np.ndarray, frequencies: np.ndarray,
                      gaussian: bool, offset: bool) -> SystemResponse:
    """The least-squares sigma and tau (module docstring) of data P_f (F, ...) given the
    fitted albedo's field A_f a (F, ...) at ``frequencies`` (F,); a term not fitted is 0."""
    f = np.asarray(frequencies, dtype=float)
    u = model.reshape(f.size, -1).astype(np.complex128)
    p = data.reshape(f.size, -1).astype(np.complex128)
    z = np.einsum("fs,fs->f", np.conj(u), p)
    e = np.einsum("fs,fs->f", np.conj(u), u).real
    f_max = float(np.abs(f).max())

    def score(sigma: float, tau: float) -> float:
        m = np.exp(-0.5 * (2 * np.pi * f * sigma) ** 2)
        num = float(np.sum(m * (np.exp(2j * np.pi * f * tau) * z).real))
        den = float(np.sum(m * m * e))
        return num * num / den if num > 0 and den > 0 else 0.0

    sigma, tau = 0.0, 0.0
    step = 1.0 / (_TAU_GRID * f_max)
    diffs = np.diff(np.unique(f))
    half = 0.5 / float(diffs.min()) if diffs.size else 0.5 / f_max
    from scipy.optimize import minimize_scalar  # not at import: the config alone is light

    for _ in range(_PASSES if gaussian and offset else 1):
        if offset:
            grid = np.arange(-half, half + step / 2, step)
            best = float(grid[int(np.argmax([score(sigma, t) for t in grid]))])
            found = minimize_scalar(lambda t, s=sigma: -score(s, t),
                                    bounds=(best - step, best + step), method="bounded",
                                    options={"xatol": step * 1e-4})
            tau = float(found.x) if -found.fun >= score(sigma, best) else best
        if gaussian:
            top = _SIGMA_MAX / (2 * np.pi * f_max)
            grid = np.linspace(0.0, top, 31)
            best = float(grid[int(np.argmax([score(s, tau) for s in grid]))])
            lo, hi = max(0.0, best - top / 30), min(top, best + top / 30)
            found = minimize_scalar(lambda s, t=tau: -score(s, t), bounds=(lo, hi),
                                    method="bounded", options={"xatol": top * 1e-5})
            sigma = float(found.x) if -found.fun >= score(best, tau) else best
    return SystemResponse(sigma, tau, gaussian, offset)


def search_response(residual: Callable[[SystemResponse], float], start: SystemResponse,
                    f_max: float, rounds: int) -> SystemResponse:
    """The response minimising ``residual`` (the data misfit after the albedo is fitted
    again with its gains): from ``start``, per round and per fitted term, a parabola through
    the residuals at the current value and a step h either side (sigma kept >= 0), its
    vertex tried too (within 2 h); the steps start at 1 / (8 f_max) and halve each round."""
    best, best_r = start, residual(start)
    step = 1.0 / (8.0 * f_max)
    names = [n for n, on in (("tau", start.offset), ("sigma", start.gaussian)) if on]
    for _ in range(rounds):
        for name in names:
            centre = float(getattr(best, name))
            xs = [centre - step, centre, centre + step]
            if name == "sigma":
                xs = [max(0.0, x) for x in xs] if centre >= step else [0.0, step / 2, step]
            ys = [best_r if x == centre else residual(_moved(best, name, x)) for x in xs]
            vertex = _vertex(xs, ys, centre, 2 * step)
            if name == "sigma":
                vertex = max(0.0, vertex)
            if all(abs(vertex - x) > 1e-6 * step for x in xs):
                xs.append(vertex)
                ys.append(residual(_moved(best, name, vertex)))
            i = int(np.argmin(ys))
            if ys[i] < best_r:
                best, best_r = _moved(best, name, xs[i]), ys[i]
        step /= 2
    return best


def _moved(response: SystemResponse, name: str, value: float) -> SystemResponse:
    return replace(response, sigma=value) if name == "sigma" else replace(response, tau=value)


def _vertex(xs: list[float], ys: list[float], centre: float, reach: float) -> float:
    """The minimum of the parabola through three points, within ``reach`` of ``centre`` (the
    lowest point where the parabola opens downwards)."""
    a = np.polyfit(np.asarray(xs), np.asarray(ys), 2)
    if not a[0] > 0:
        return float(xs[int(np.argmin(ys))])
    return float(np.clip(-a[1] / (2 * a[0]), centre - reach, centre + reach))


def with_gains(response: SystemResponse | None, f: np.ndarray, fields: np.ndarray
               ) -> np.ndarray:
    """Fields (F, ...) at frequencies f times the response's gains (unchanged for None)."""
    if response is None:
        return fields
    return fields * response.gains(f).reshape((-1,) + (1,) * (fields.ndim - 1))

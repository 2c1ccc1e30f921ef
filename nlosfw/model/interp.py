"""The ``interp`` baseline: cubic-spline interpolation of the complex field in x, y and f.

Every neural field is reported next to it: a neural field earns its place only
where it beats this. The field is interpolated as a tensor-product cubic spline
(not-a-knot end conditions, :class:`scipy.interpolate.CubicSpline`) over the
training grid's y, x and frequency axes; real and imaginary parts are
interpolated together (the spline is linear in the data). Axes with two
samples fall back to linear interpolation, axes with one sample to a constant.
By default the field is first demodulated by its common path delay (the same
normalisation the neural models use, :func:`nlosfw.model.neural.normalisation.estimate_delay`),
so that the comparison isolates what the networks add.

Scattered wall samples (a random scan: a field with one row of wall points, see
:mod:`nlosfw.evaluation.splits`) are interpolated in frequency by the same spline and in
space by Clough-Tocher's piecewise-cubic C1 interpolant on the samples' Delaunay
triangulation (:class:`scipy.interpolate.CloughTocher2DInterpolator`, what
``griddata(method="cubic")`` uses), on the complex, demodulated field, every frequency
at once. Outside the samples' convex hull (or with fewer than three samples, or
collinear ones) a query takes the nearest sample's value; ``extrapolation: cubic`` needs
a rectilinear grid and is refused for scattered samples.

Outside the training hull (``extrapolation``):

* ``nearest`` (default): query coordinates and frequencies are clamped to the
  hull, so the value at the nearest edge sample (or edge frequency) is repeated.
* ``cubic``: the spline's end pieces are continued (cubic polynomial
  extrapolation); exact for cubic fields, but on phasor fields it amplifies
  aliased edge samples (thesis split of the two-planes benchmark: held-out pixel
  error 0.65 with ``cubic`` against 0.26 with ``nearest``, all of the difference in
  the last row and column, which lie half a training step outside the hull) and
  it diverges when extrapolating a band of frequencies (``tail`` split).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import Delaunay

from nlosfw.common.config import Choice
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.interface import (
    FieldModel,
    FieldModelConfig,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, write_model_file
from nlosfw.model.neural.normalisation import estimate_delay
from nlosfw.transform.field import PhasorField

#: Frequencies interpolated at once (bounds memory to about F_chunk * points * X values).
_FREQ_CHUNK = 8


class Extrapolation(Choice):
    """Outside the training hull: clamp to the hull, or continue the cubic end pieces."""

    nearest = "nearest"
    cubic = "cubic"


@dataclass(frozen=True)
class InterpConfig(FieldModelConfig):
    """Options of the interpolation baseline (``seed`` and ``device`` are ignored)."""

    extrapolation: Extrapolation = Extrapolation.nearest
    """Outside the training hull: clamp to the hull, or continue the cubic end pieces."""
    demodulate: bool = True
    """Interpolate P e^{+2 pi i f tau} (tau the field's common path delay, as the neural
    models do) and put the carrier back afterwards: the spline in f then follows a field
    that turns far less between frequency samples."""


def spline_weights(knots: np.ndarray, queries: np.ndarray, extrapolation: str) -> np.ndarray:
    """Matrix W (Q, N) with W @ values = the cubic spline through (knots, values) at queries.

    ``knots`` must be strictly increasing. Two knots give linear, one a constant.
    """
    knots = np.asarray(knots, dtype=np.float64)
    q = np.asarray(queries, dtype=np.float64)
    n = knots.size
    if n == 1:
        return np.ones((q.size, 1))
    if extrapolation == "nearest":
        q = np.clip(q, knots[0], knots[-1])
    if n == 2:
        t = (q - knots[0]) / (knots[1] - knots[0])
        return np.stack([1 - t, t], axis=1)
    from scipy.interpolate import CubicSpline  # not at import: the config alone is light

    return CubicSpline(knots, np.eye(n), axis=0, extrapolate=True)(q)


def _rectilinear_axes(wall_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(x of columns, y of rows) if ``wall_xyz[y, x]`` is a rectilinear grid, else None."""
    xs, ys = wall_xyz[0, :, 0], wall_xyz[:, 0, 1]
    scale = max(float(np.ptp(wall_xyz[..., :2])), 1e-12)
    ok = (np.allclose(wall_xyz[..., 0], xs[None, :], atol=1e-6 * scale)
          and np.allclose(wall_xyz[..., 1], ys[:, None], atol=1e-6 * scale))
    return (xs, ys) if ok else None


@dataclass(frozen=True, eq=False)
class _Samples:
    """The stored field: demodulated values (F, Y, X) on increasing axes x, y, f."""

    values: np.ndarray
    x: np.ndarray
    y: np.ndarray
    f: np.ndarray
    delay: float = 0.0


@dataclass(frozen=True, eq=False)
class _Scattered:
    """The stored field of scattered samples: demodulated values (F, N) at points (N, 2)
    and increasing frequencies f, with their triangulation (None: nearest only)."""

    values: np.ndarray
    points: np.ndarray
    f: np.ndarray
    delay: float = 0.0
    triangulation: Delaunay | None = None


def _triangulation(points: np.ndarray) -> Delaunay | None:
    """The Delaunay triangulation of the points, or None when there is none (fewer than
    three points, or all on one line)."""
    if points.shape[0] < 3:
        return None
    from scipy.spatial import Delaunay, QhullError  # not at import: the config alone is light

    try:
        return Delaunay(points)
    except QhullError:
        return None


class InterpFieldModel(FieldModel[InterpConfig]):
    """Tensor-product cubic spline of the complex field over (y, x, f), or Clough-Tocher
    over scattered samples; see the module doc."""

    config_class = InterpConfig

    def __init__(self, config: InterpConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._samples: _Samples | _Scattered | None = None

    def _stored(self) -> _Samples | _Scattered:
        if self._samples is None:
            raise FitError("interp: call fit() or load() before predict() or save()")
        return self._samples

    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Store the field on its (sorted) rectilinear grid, or its scattered samples;
        ``validation`` is unused."""
        check_training_field(field, "interp")
        f = field.frequencies
        of = np.argsort(f)
        if f.size > 1 and np.any(np.diff(f[of]) <= 0):
            raise DataError("interp: the training field's frequencies repeat a value")
        axes = _rectilinear_axes(field.wall_xyz)
        if axes is None:
            self._samples = self._scattered(field, of)
        else:
            xs, ys = axes
            ox, oy = np.argsort(xs), np.argsort(ys)
            for name, a in (("x", xs[ox]), ("y", ys[oy])):
                if a.size > 1 and np.any(np.diff(a) <= 0):
                    raise DataError(f"interp: the training field's {name} repeat a value")
            values = field.values[of][:, oy][:, :, ox].astype(np.complex128)
            delay = estimate_delay(values, f[of]) if self.config.demodulate else 0.0
            self._samples = _Samples(values * np.exp(2j * np.pi * f[of] * delay)[:, None, None],
                                     xs[ox], ys[oy], f[of], delay)
        if on_step is not None:
            on_step(TrainingStep(step=1, total_steps=1, loss=0.0))
        return FitReport(steps=1, seconds=0.0, final_loss=0.0)

    def _scattered(self, field: PhasorField, order: np.ndarray) -> _Scattered:
        """The field's wall samples as scattered points (any layout of wall points)."""
        if self.config.extrapolation == Extrapolation.cubic:
            raise FitError("interp: extrapolation cubic needs the training samples on a "
                           "rectilinear grid; these are scattered (use extrapolation nearest)")
        points = field.wall_xyz[..., :2].reshape(-1, 2)
        if np.unique(points, axis=0).shape[0] != points.shape[0]:
            raise DataError("interp: the training field has two samples at the same wall point")
        f = field.frequencies[order]
        values = field.values[order].reshape(f.size, -1).astype(np.complex128)
        delay = estimate_delay(values, f) if self.config.demodulate else 0.0
        return _Scattered(values * np.exp(2j * np.pi * f * delay)[:, None], points, f, delay,
                          _triangulation(points))

    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """The interpolant at wall points (..., 2) and frequencies (F,) -> complex (F, ...)."""
        xy, f = check_query(wall_xy, frequencies, "interp")
        stored = self._stored()
        mode = self.config.extrapolation
        pts = xy.reshape(-1, 2)
        wf = spline_weights(stored.f, f, mode)                    # (F', F)
        if isinstance(stored, _Scattered):
            out = _scattered_predict(stored, wf @ stored.values, pts)
            out *= np.exp(-2j * np.pi * f * stored.delay)[:, None]
            return out.reshape((f.size, *xy.shape[:-1]))
        wx = spline_weights(stored.x, pts[:, 0], mode)             # (P, X)
        wy = spline_weights(stored.y, pts[:, 1], mode)             # (P, Y)
        out = np.empty((f.size, pts.shape[0]), dtype=np.complex128)
        for k in range(0, f.size, _FREQ_CHUNK):
            sl = slice(k, k + _FREQ_CHUNK)
            v = np.tensordot(wf[sl], stored.values, axes=(1, 0))  # (f, Y, X)
            rows = np.matmul(wy[None].astype(np.complex128), v)  # (f, P, X)
            out[sl] = np.einsum("fpx,px->fp", rows, wx)
        out *= np.exp(-2j * np.pi * f * stored.delay)[:, None]
        return out.reshape((f.size, *xy.shape[:-1]))

    @property
    def n_parameters(self) -> int:
        """Stored real values: 2 per complex training sample."""
        if self._samples is None:
            raise FitError("interp: the number of stored values is known after fit or load")
        return int(2 * self._samples.values.size)

    def save(self, path: str | Path) -> None:
        stored = self._stored()
        if isinstance(stored, _Scattered):
            write_model_file(path, "interp", self.config,
                             {"values": stored.values, "points": stored.points, "f": stored.f},
                             {"delay": stored.delay})
            return
        write_model_file(path, "interp", self.config,
                         {"values": stored.values, "x": stored.x, "y": stored.y, "f": stored.f},
                         {"delay": stored.delay})

    @classmethod
    def load(cls, path: str | Path) -> InterpFieldModel:
        from nlosfw.common.config import config_from_mapping

        header, arrays = read_model_file(path, "interp")
        try:
            model = cls(config_from_mapping(InterpConfig, header["config"], "model"))
            delay = float(header.get("delay", 0.0))
            if "points" in arrays:
                values, points, f = (arrays[k] for k in ("values", "points", "f"))
            else:
                values, x, y, f = (arrays[k] for k in ("values", "x", "y", "f"))
        except Exception as err:
            raise DataError(f"model file {path}: invalid interp file ({type(err).__name__})"
                            ) from None
        if "points" in arrays:
            if (points.ndim != 2 or points.shape[1] != 2
                    or values.shape != (f.size, points.shape[0])
                    or not np.all(np.isfinite(values))):
                raise DataError(f"model file {path}: values of shape {values.shape} do not "
                                f"match {f.size} frequencies and points {points.shape}")
            model._samples = _Scattered(values.astype(np.complex128), points, f, delay,
                                        _triangulation(points))
            return model
        if values.shape != (f.size, y.size, x.size) or not np.all(np.isfinite(values)):
            raise DataError(f"model file {path}: values of shape {values.shape} do not match "
                            f"the axes ({f.size}, {y.size}, {x.size})")
        model._samples = _Samples(values.astype(np.complex128), x, y, f, delay)
        return model


def _scattered_predict(stored: _Scattered, values: np.ndarray, points: np.ndarray
                       ) -> np.ndarray:
    """Scattered samples' ``values`` (F, N) interpolated at ``points`` (P, 2) -> (F, P):
    Clough-Tocher inside the samples' hull, the nearest sample outside it."""
    out = np.full((values.shape[0], points.shape[0]), np.nan, dtype=np.complex128)
    if stored.triangulation is not None:
        from scipy.interpolate import CloughTocher2DInterpolator

        out[:] = CloughTocher2DInterpolator(stored.triangulation, values.T)(points).T
    outside = np.isnan(out[0].real)
    if np.any(outside):
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(stored.points).query(points[outside])
        out[:, outside] = values[:, nearest]
    return out

"""A smooth additive background for ``rsd_prior``: one complex offset b_f per frequency.

With ``background: constant`` the model's field is A(rho)(x, f) + b_f, b_f the same at
every wall point x. A background that is constant in time over the whole histogram only
adds to its DC bin, which no phasor field holds; but ambient light and dark counts summed
over a gated window shorter than the histogram, and a late-time tail (the system's slow
response, inter-reflections off the room), are smooth in time, so their spectra sit at the
low frequencies, and smooth over the wall: a field that varies slowly over the wall. A
constant per frequency over the wall is the simplest model of it (the zeroth order of a
low-order polynomial over the wall).

The offsets are unconstrained, so they are minimised out exactly (variable projection):
for a fixed albedo the least-squares offset of the loss 1/2 sum_f ||A_f a + b_f - P_f||^2
(every kept sample weighted alike) is the mean over the kept samples of the residual at f,

    b_f = mean_x (P_f(x) - A_f a(x)),

and putting it back leaves 1/2 ||Q_f (A_f a - P_f)||^2 with Q_f = I - v_f v_f^H / N the
projection that removes a wall-constant part (N kept samples). FISTA then runs on the
operator Q A and the data Q P (Q is an orthogonal projection, so (Q A)^H = A^H Q): the
albedo and the offsets are the joint minimiser, and the offsets follow from the albedo.
When the device legs are taken out of the field before the fit, a raw offset b_f becomes
b_f v_f(x) with v_f = exp(2 pi i f legs(x)) (|v_f| = 1), and the mean above is of
conj(v_f) times the residual, i.e. of the raw residual: the same least squares.

Offsets are fitted at every training frequency (after the albedo, each by the mean above);
at other frequencies the prediction interpolates their magnitude and unwrapped phase
linearly (the nearest end value beyond the band): a tail delayed by a path d has a phase
-2 pi f d, which real and imaginary parts interpolated would shrink between samples.

What the offsets change on the shared captures, and why a plane per frequency over the
wall is not offered: ``studies/physics_terms_measured/README.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import Choice
from nlosfw.model.physics.wall import WallSamples
from nlosfw.transform.field import PhasorField
from nlosfw.transform.temporal_dft import unit_phasor


class Background(Choice):
    """The additive background term of ``rsd_prior`` (see the module docstring)."""

    none = "none"
    constant = "constant"


@dataclass(frozen=True, eq=False)
class WallBackground:
    """Fitted offsets b_f (raw field units), constant over the wall, one per frequency."""

    frequencies: np.ndarray
    """(F,) ascending training frequencies (cycles per metre)."""
    values: np.ndarray
    """(F,) complex offsets."""

    def at(self, frequencies: np.ndarray) -> np.ndarray:
        """b at ``frequencies``: magnitude and unwrapped phase linear in f between the
        fitted ones (exact for a delayed offset), the end values beyond."""
        f = np.asarray(frequencies, dtype=float)
        magnitude = np.interp(f, self.frequencies, np.abs(self.values))
        phase = np.interp(f, self.frequencies, np.unwrap(np.angle(self.values)))
        return magnitude * np.exp(1j * phase)

    def summary(self, field_rms: float) -> dict[str, float]:
        """The fitted offsets for the fit report: RMS and largest |b_f| over the training
        frequencies, each as a ratio to the field's RMS over the kept samples."""
        magnitude = np.abs(self.values)
        rms = float(np.sqrt(np.mean(magnitude ** 2)))
        return {"background_rms_ratio": rms / field_rms,
                "background_max_ratio": float(magnitude.max()) / field_rms}


class BackgroundProjection:
    """The projections Q_f and the offsets of a wall (canonical order) in the fit's domain."""

    def __init__(self, legs: np.ndarray | None, wall_shape: tuple[int, ...],
                 mask: np.ndarray | None = None) -> None:
        """``legs``: the device path (m) at each wall sample when the fit takes it out of the
        field (None otherwise); ``wall_shape``: the wall's (Y, X); ``mask``: the sampled
        points of the wall (None: all), the only ones the offsets are fitted on and added to."""
        self._legs = legs
        self._shape = tuple(wall_shape)
        self._mask = None if mask is None else np.asarray(mask, dtype=bool)

    def _basis(self, frequencies: np.ndarray, dtype: type) -> np.ndarray | None:
        """v_f(x), (F, Y, X); None where it is 1 everywhere (no device legs)."""
        if self._legs is None:
            return None
        f = np.asarray(frequencies, dtype=float)
        return unit_phasor(f[:, None, None] * self._legs[None], dtype)

    def offsets(self, frequencies: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """The least-squares b_f of a residual P - A a (F, Y, X) in the fit's domain, (F,)."""
        return _mean(self._basis(frequencies, residual.dtype.type), residual, self._mask)

    def projector(self, frequencies: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """p -> Q p for fields (F, Y, X) at ``frequencies`` (a new array)."""
        cache: dict[type, np.ndarray | None] = {}

        def project(p: np.ndarray) -> np.ndarray:
            kind = p.dtype.type
            if kind not in cache:
                cache[kind] = self._basis(frequencies, kind)
            v = cache[kind]
            b = _mean(v, p, self._mask).astype(p.dtype)[:, None, None]
            offset = b if v is None else b * v
            return p - (offset if self._mask is None else offset * self._mask)

        return project


def background_projection(background: Background, field: PhasorField,
                          samples: WallSamples) -> BackgroundProjection | None:
    """The projection of a training ``field`` on its wall grid ``samples`` for
    ``background`` (None for none)."""
    if background == Background.none:
        return None
    geometry = field.geometry
    legs = (samples.on_grid(geometry.device_path(field.wall_xyz))
            if geometry.t_accounts_first_and_last_bounces else None)
    return BackgroundProjection(legs, samples.layout.shape, samples.mask)


def fit_offsets(projection: BackgroundProjection,
                forward: Callable[[np.ndarray], np.ndarray], frequencies: np.ndarray,
                values: np.ndarray, scale: float, chunk: int = 16) -> WallBackground:
    """The offsets at every training frequency for a fitted albedo: ``forward(f)`` is its
    field A_f a (canonical wall order) at frequencies ``f``, ``values`` the training field
    (F, Y, X) in the fit's domain divided by ``scale``; ``chunk`` frequencies at a time."""
    f = np.asarray(frequencies, dtype=float)
    parts = [projection.offsets(f[i:i + chunk], values[i:i + chunk] - forward(f[i:i + chunk]))
             for i in range(0, f.size, chunk)]
    b = np.concatenate(parts).astype(np.complex128) * scale
    order = np.argsort(f, kind="stable")
    return WallBackground(f[order], b[order])


def _mean(v: np.ndarray | None, p: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """mean_x conj(v_f(x)) p_f(x) for every f over the points of ``mask`` (v None: 1;
    mask None: every point)."""
    r = p if v is None else np.conj(v) * p
    if mask is not None:
        return np.asarray(r[:, mask].mean(axis=1))
    return np.asarray(r.reshape(r.shape[0], -1).mean(axis=1))

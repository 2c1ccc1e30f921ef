"""The ``lct`` (light-cone transform, O'Toole et al. 2018) and ``fbp`` (filtered
backprojection) imagers, on the field's confocal transient (:mod:`nlosfw.image.transient`).

With d = t/2 the distance (path t) and the hidden albedo rho(x, y, z), a confocal
transient with 1/r^n falloff is

    h(x_s, d) = integral rho(x, y, z) / r^n delta(r - d),   r = |(x, y, z) - x_s|.

Substituting v = d^2 and u = z^2 (delta(r - d) = 2 d delta(r^2 - v)) turns it into a
3-D convolution with the light cone:

    R_t(x_s, v) = d^(n-1) h(x_s, d)       (data, resampled uniformly in v)
    R_z(x, u)   = rho(x, sqrt u) / sqrt u  (unknown)
    R_t = K * R_z,   K(x, y, v) = delta(x^2 + y^2 - v).

``lct`` inverts it with the Wiener filter conj(K^)/(|K^|^2 + 1/snr) (K normalised to
unit energy, as in the published code, so ``snr`` means the same) and returns
rho(z) = z R_z(z^2). ``fbp`` applies the adjoint conj(K^) (backprojection) and then
the Laplacian along depth, -d^2/dz^2, on a uniform depth grid (the high-pass of the
"filtered" backprojection the LCT and f-k papers compare with). The Laplacian amplifies
the top of the band, where a measured capture holds mostly photon noise, so ``fbp`` first
weights each frequency of the field by its Wiener weight (``wiener``, on by default), the
share of its power that is signal, measured from the field's evanescent region
(:mod:`nlosfw.image.evanescent`); on the diffuse S that turns a front view of noise (NCC
-0.13 with the authors' LCT) into the S (0.94), and a noise-free field is left as it is.

Discretisation: v is sampled at v_j = j dv, j < M, each sample the average of the
transient (linearly interpolated in t) over its bin; K puts each lateral offset's
cone point on its two nearest v samples (linear weights); both are zero-padded to
twice their size so the convolution is linear. M is chosen so that the depth step
dv / (2 z) at the nearest voxel is at most the transient's, dt / 2 (capped at
``max_bins``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar, TypeVar

import numpy as np
import scipy.fft
import scipy.sparse

from nlosfw.common.config import require
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.image.arrays import ArrayOps, interpolate_depths_on
from nlosfw.image.data_settings import DEFAULT_SNR
from nlosfw.image.evanescent import evanescent_noise_weights
from nlosfw.image.transient import (
    TransientImager,
    TransientImagerConfig,
    WallGrid,
    field_hints,
    interpolate_depths,
    transient_sizes,
    wall_shape,
)
from nlosfw.transform.field import PhasorField

#: Depth steps (dt/2) of margin beyond the farthest voxel.
_MARGIN_STEPS = 4


@dataclass(frozen=True)
class LightConeConfig(TransientImagerConfig):
    """Options shared by ``lct`` and ``fbp``."""

    max_bins: int = 2048
    """Most samples along v = d^2 (memory: 16 x 8 bytes x this x wall samples)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.max_bins >= 16, "max_bins", f"must be >= 16, got {self.max_bins}")


@dataclass(frozen=True)
class LCTImagerConfig(LightConeConfig):
    """Options of the ``lct`` imager."""

    snr: float | None = None
    """Signal-to-noise ratio of the Wiener filter conj(K^)/(|K^|^2 + 1/snr); null: the
    capture's imaging hint when it states one, else estimated from the field's evanescent
    noise (nlosfw.image.data_settings; O'Toole's demo sets 0.8 retroreflective, 0.08
    diffuse by hand)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.snr is None or (math.isfinite(self.snr) and self.snr > 0), "snr",
                f"must be a finite number > 0 (or null: the capture's hint), got {self.snr}")


@dataclass(frozen=True)
class FBPImagerConfig(LightConeConfig):
    """Options of the ``fbp`` imager."""

    wiener: bool = True
    """Weight each frequency by the share of its power that is signal, measured from the
    field's evanescent region (noise only), before the depth Laplacian; false: the plain
    Laplacian of every frequency (noise included)."""


@dataclass(frozen=True, eq=False)
class _Cone:
    """The v grid of one reconstruction: M samples dv apart, padded FFT shape, and the
    transient's time step dt it is made for."""

    m: int
    dv: float
    shape: tuple[int, int, int]
    dt: float
    """The transient's time step it was made for (m of path)."""


LightConeConfigT = TypeVar("LightConeConfigT", bound=LightConeConfig)


class LightConeImager(TransientImager[LightConeConfigT]):
    """What ``lct`` and ``fbp`` share: the resampled data and the light-cone kernel."""

    config_class: ClassVar[type] = LightConeConfig

    def _cone(self, grid: WallGrid, depths: np.ndarray, dt: float) -> _Cone:
        return light_cone(grid.shape, grid.lateral_reach, (float(depths.min()),
                                                          float(depths.max())),
                          dt, self.config.max_bins)

    @classmethod
    def estimate_memory(cls, config: LightConeConfigT, shape: PlanShape,
                        planes: int) -> MemoryEstimate:
        """The padded light-cone volume (:func:`light_cone_memory`): the data's spectrum,
        the cone's cached spectrum and, for the Wiener filter, its terms."""
        return light_cone_memory(config, shape, wiener=isinstance(config, LCTImagerConfig))

    def _cone_volume(self, field: PhasorField, grid: WallGrid, cone: _Cone,
                     window: tuple[float, float], snr: float | None,
                     positions: np.ndarray) -> np.ndarray:
        """R_z (Wiener-inverted with ``snr``, or backprojected: None) interpolated linearly
        at ``positions`` along v, (len(positions), Y, X); on the bound array backend's
        device when there is one (:meth:`_cone_volume_on`)."""
        if self.arrays is None:
            data = self._resampled(field, grid, cone, cone.dt, window)
            r_z = self._convolved(data, grid, cone, snr)
            return interpolate_depths(r_z, 0.0, cone.dv, positions)
        n_t = math.ceil(2 * math.sqrt(cone.m * cone.dv) / cone.dt) + 2
        rows = _v_resampling(cone, cone.dt, n_t) @ self.window_coefficients(
            field, np.arange(n_t) * cone.dt, window)                         # (M, F)
        return self._cone_volume_on(self.arrays, np.asarray(rows), grid, cone, snr,
                                    positions)

    def _cone_volume_on(self, ops: ArrayOps, rows: np.ndarray, grid: WallGrid, cone: _Cone,
                        snr: float | None, positions: np.ndarray) -> np.ndarray:
        """:meth:`_cone_volume` on the device of ``ops``: the resampled transient, ``rows``
        (M, F) (the v bins' averages of the transient's coefficient rows) times the wall's
        values, its FFT, the product with the light cone's filter and the inverse FFT."""
        flat = ops.asarray(grid.values.reshape(grid.values.shape[0], -1), np.complex64)
        data = (ops.asarray(rows, np.complex64) @ flat).reshape((cone.m,) + grid.shape)
        spectrum = ops.fftn(data, cone.shape, (0, 1, 2))
        del data
        k = ops.asarray(self._kernel_spectrum(grid, cone), np.complex64)
        if snr is None:
            spectrum = spectrum * k.conj()
        else:
            spectrum = spectrum * (k.conj() / (k.real * k.real + k.imag * k.imag + 1.0 / snr))
        del k
        ny, nx = grid.shape
        r_z = ops.ifftn(spectrum, (0, 1, 2))[:cone.m, :ny, :nx]
        return interpolate_depths_on(ops, r_z, 0.0, cone.dv, positions)

    def _resampled(self, field: PhasorField, grid: WallGrid, cone: _Cone, dt: float,
                   window: tuple[float, float]) -> np.ndarray:
        """R_t: the falloff-compensated transient averaged over each v bin, (M, Y, X)."""
        n_t = math.ceil(2 * math.sqrt(cone.m * cone.dv) / dt) + 2
        h = self.transient(field, grid, np.arange(n_t) * dt, window)
        matrix = _v_resampling(cone, dt, n_t)
        out = matrix @ h.reshape(n_t, -1)
        return np.asarray(out, dtype=np.complex64).reshape((cone.m,) + grid.shape)

    def _convolved(self, data: np.ndarray, grid: WallGrid, cone: _Cone,
                   snr: float | None) -> np.ndarray:
        """R_z (M, Y, X): Wiener-inverted (``snr``) or backprojected (None) data."""
        workers = self.config.workers
        spectrum = scipy.fft.fftn(data, s=cone.shape, workers=workers, overwrite_x=False)
        k = self._kernel_spectrum(grid, cone)
        if snr is None:
            spectrum *= np.conj(k)
        else:
            spectrum *= np.conj(k) / (np.abs(k) ** 2 + 1.0 / snr)
        out = scipy.fft.ifftn(spectrum, workers=workers, overwrite_x=True)
        ny, nx = grid.shape
        return out[:cone.m, :ny, :nx]

    def _kernel_spectrum(self, grid: WallGrid, cone: _Cone) -> np.ndarray:
        """FFT of the light cone K on the padded grid (unit energy), cached per geometry (the
        last two: the falloff's estimate images a binned wall before the image's own)."""
        key = (cone.m, cone.dv, cone.shape, grid.shape, grid.spacing)
        cache: dict[tuple[object, ...], np.ndarray] = self.__dict__.setdefault("_kernel_cache", {})
        if key not in cache:
            while len(cache) >= 2:
                del cache[next(iter(cache))]               # the oldest geometry
            cache[key] = _light_cone_spectrum(grid, cone, self.config.workers)
        return cache[key]


class LCTImager(LightConeImager[LCTImagerConfig]):
    """Light-cone transform with a Wiener filter (O'Toole 2018), confocal fields."""

    config_class = LCTImagerConfig
    imager_name = "lct"
    estimates_snr = True

    def _planes(self, field: PhasorField, grid: WallGrid, depths: np.ndarray, dt: float,
                window: tuple[float, float]) -> tuple[np.ndarray, dict[str, object]]:
        cone = self._cone(grid, depths, dt)
        snr = self.snr_for(field)
        volume = (self._cone_volume(field, grid, cone, window, snr, depths**2)
                  * depths[:, None, None])
        return volume, {"v_samples": cone.m, "fft_shape": list(cone.shape), "snr": snr,
                        **self.device_info()}

    def snr_for(self, field: PhasorField) -> float:
        """The Wiener SNR for ``field``: the ``snr`` option if set, else the field's imaging
        hint (:meth:`reconstruct` puts the estimate from the data there when the capture
        states none), else :data:`DEFAULT_SNR`."""
        if self.config.snr is not None:
            return float(self.config.snr)
        hint = field_hints(field).snr
        return DEFAULT_SNR if hint is None else float(hint)


class FBPImager(LightConeImager[FBPImagerConfig]):
    """Backprojection (the light cone's adjoint) and a Laplacian along depth, confocal fields."""

    config_class = FBPImagerConfig
    imager_name = "fbp"
    tapers_end = True

    def _planes(self, field: PhasorField, grid: WallGrid, depths: np.ndarray, dt: float,
                window: tuple[float, float]) -> tuple[np.ndarray, dict[str, object]]:
        info: dict[str, object] = {}
        if self.config.wiener:
            noise = evanescent_noise_weights(grid.values, field.frequencies, grid.spacing)
            weights = noise.weights.astype(grid.values.real.dtype)
            grid = dataclasses.replace(grid, values=grid.values * weights[:, None, None])
            info["wiener"] = {"frequencies_measured": noise.measured,
                              "noise_power": noise.noise_power,
                              "weights": [round(float(w), 4) for w in noise.weights]}
        cone = self._cone(grid, depths, dt)
        dz = dt / 2
        z = np.arange(float(depths.min()) - dz, float(depths.max()) + 2 * dz, dz)
        rho = self._cone_volume(field, grid, cone, window, None, z**2) * z[:, None, None]
        laplacian = (2 * rho[1:-1] - rho[:-2] - rho[2:]) / (dz * dz)
        volume = interpolate_depths(laplacian, float(z[1]), dz, depths)
        return volume, {"v_samples": cone.m, "fft_shape": list(cone.shape),
                        "filter": "-d2/dz2", **info, **self.device_info()}


def light_cone(wall: tuple[int, int], reach: float, depths: tuple[float, float], dt: float,
               max_bins: int) -> _Cone:
    """The v grid of planes at ``depths`` (nearest, farthest; m) behind a ``wall`` (ny, nx)
    whose samples lie at most ``reach`` (m) apart laterally, for a transient of time step
    ``dt``: M samples (at most ``max_bins``) and the padded FFT shape."""
    dz = dt / 2
    far = math.hypot(depths[1] + _MARGIN_STEPS * dz, reach)          # largest distance
    near = max(depths[0], dz)
    m = math.ceil(far * far / (2 * near * dz))
    m = int(min(max(m, math.ceil(far / dz), 16), max_bins))
    ny, nx = wall
    shape = (scipy.fft.next_fast_len(2 * m), scipy.fft.next_fast_len(2 * ny) if ny > 1
             else 1, scipy.fft.next_fast_len(2 * nx) if nx > 1 else 1)
    return _Cone(m=m, dv=far * far / m, shape=shape, dt=dt)


def light_cone_memory(config: LightConeConfig, shape: PlanShape,
                      wiener: bool) -> MemoryEstimate:
    """What ``lct`` (``wiener``) or ``fbp`` holds at its peak for a run of ``shape``: P, the
    padded complex64 volume, about 4.5 times (the data's spectrum, the cone's cached
    spectrum, its conjugate, the filter's denominator and quotient) for the Wiener filter,
    3 times for the adjoint; and the transient and its resampling. The v samples at their
    most (``max_bins``) when the band or the depths are not known yet."""
    wall = wall_shape(shape)
    reach, depths, dt = transient_sizes(config, shape)
    if depths is None or dt is None:
        m = config.max_bins
        padded = (scipy.fft.next_fast_len(2 * m),) + tuple(
            scipy.fft.next_fast_len(2 * n) if n > 1 else 1 for n in wall)
        why = f"at most {m} v samples (max_bins)"
    else:
        cone = light_cone(wall, reach, depths, dt, config.max_bins)
        m, padded = cone.m, cone.shape
        why = f"{m} v samples"
    volume = 8.0 * float(np.prod(padded))
    samples = 8.0 * wall[0] * wall[1]
    factor = 4.5 if wiener else 3.0
    return MemoryEstimate((
        MemoryPart("the light-cone volumes", f"{factor:g} x the padded volume "
                   f"{' x '.join(map(str, padded))} (complex64; {why})", factor * volume),
        MemoryPart("the transient resampled", f"{m} v samples and the transient on "
                   f"{wall[0]} x {wall[1]} wall points", 4.0 * m * samples),
    ))


def _v_resampling(cone: _Cone, dt: float, n_t: int) -> scipy.sparse.csr_matrix:
    """(M, n_t) sparse: each v bin's average of the transient, linearly interpolated in t."""
    dv = cone.dv
    # enough sub-samples that the widest bin (the first: t from 0 to 2 sqrt(dv/2)) is
    # sampled at least once per time step
    sub = int(math.ceil(2 * math.sqrt(dv / 2) / dt)) + 1
    j = np.arange(cone.m)[:, None]
    v = np.clip((j + (np.arange(sub)[None, :] + 0.5) / sub - 0.5) * dv, 0.0, None)
    pos = 2 * np.sqrt(v) / dt                                   # t / dt
    i0 = np.floor(pos).astype(np.int64)
    frac = pos - i0
    rows = np.repeat(np.arange(cone.m), sub)
    rows = np.concatenate([rows, rows])
    cols = np.concatenate([i0.ravel(), i0.ravel() + 1])
    weights = np.concatenate([(1 - frac).ravel(), frac.ravel()]) / sub
    keep = cols < n_t
    return scipy.sparse.csr_matrix((weights[keep], (rows[keep], cols[keep])),
                                   shape=(cone.m, n_t))


def _light_cone_spectrum(grid: WallGrid, cone: _Cone, workers: int) -> np.ndarray:
    """FFT of K(x, y, v) = delta(x^2 + y^2 - v) on the padded grid, unit energy."""
    ny, nx = grid.shape
    dy, dx = grid.spacing
    iy = np.arange(-(ny - 1), ny)
    ix = np.arange(-(nx - 1), nx)
    w = ((iy[:, None] * dy) ** 2 + (ix[None, :] * dx) ** 2) / cone.dv
    k0 = np.floor(w).astype(np.int64)
    frac = w - k0
    kernel = np.zeros(cone.shape, dtype=np.complex64)
    yy = np.broadcast_to(iy[:, None] % cone.shape[1], w.shape)
    xx = np.broadcast_to(ix[None, :] % cone.shape[2], w.shape)
    for k, weight in ((k0, 1 - frac), (k0 + 1, frac)):
        ok = k < cone.m
        np.add.at(kernel, (k[ok], yy[ok], xx[ok]), weight[ok])
    kernel /= np.linalg.norm(kernel)
    return scipy.fft.fftn(kernel, workers=workers, overwrite_x=True)

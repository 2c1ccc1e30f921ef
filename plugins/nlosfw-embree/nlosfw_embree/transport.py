"""Vectorised three-bounce transport for batches of hidden-surface samples.

Every sample p (area dA, albedo rho, normal n) is shared by all sensors x_s of
the wall grid. Following :mod:`nlosfw.simulate.physics`, a laser spot x_l -> p -> x_s
path carries

    rho dA cos_l cos_in cos_out cos_s / (pi^3 r_l^2 r_s^2),

counted when x_l and x_s see the same side of the surface and both legs are
unobstructed. The laser leg is evaluated once per sample (:func:`laser_side`).
The sensor legs of a batch of B samples are evaluated one grid row at a time
(Y sensors x B samples) by :class:`SingleSpotRows`, using that the wall is
the plane z = 0 (cos_s = p_z / r_s) and that the grid is separable in x and y,
with float32 buffers reused across rows, one Embree occlusion query per row,
and one ``bincount`` per row into that row's histogram slice. Each sensor's
histogram has ``bins + 2`` slots: slot 0 collects paths shorter than the
window and occluded rays, slot ``bins + 1`` longer paths; both are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw_embree.tracer import OcclusionTracer

_INV_PI3 = 1.0 / np.pi**3
#: tfar of rays that may run to infinity (nothing lies behind the wall).
_FAR = np.float32(1e30)


@dataclass(frozen=True, eq=False)
class LitSamples:
    """Surface samples reached by the laser, with what the sensor legs need (float32)."""

    origin: np.ndarray
    """(n, 3) the sample moved ``ray_offset`` off its surface, on the laser's side."""
    position: np.ndarray
    """(n, 3) the sample p."""
    normal: np.ndarray
    """(n, 3) unit normal turned towards the laser's side."""
    gain: np.ndarray
    """(n,) rho dA cos_l |cos_in| / (pi^3 r_l^2) * p_z / delta_t^4 (sensor-side units)."""
    offset: np.ndarray
    """(n,) (r_l + fixed path - t_start) / delta_t + 1: bin slot of the laser leg."""

    @property
    def n(self) -> int:
        return int(self.gain.shape[0])

    def batch(self, start: int, size: int) -> LitSamples:
        """Samples ``start`` to ``start + size`` (views)."""
        sl = slice(start, start + size)
        return LitSamples(self.origin[sl], self.position[sl], self.normal[sl], self.gain[sl],
                          self.offset[sl])

    def padded(self, multiple: int) -> LitSamples:
        """The samples padded with zero-gain copies of the first to a multiple of ``multiple``."""
        extra = (-self.n) % multiple
        if extra == 0 or self.n == 0:
            return self

        def pad(a: np.ndarray) -> np.ndarray:
            return np.concatenate([a, np.repeat(a[:1], extra, axis=0)])

        gain = np.concatenate([self.gain, np.zeros(extra, self.gain.dtype)])
        return LitSamples(pad(self.origin), pad(self.position), pad(self.normal), gain,
                          pad(self.offset))


@dataclass(frozen=True, eq=False)
class SurfaceSamples:
    """Hidden-surface samples: positions p (n, 3), unit normals (n, 3), and albedo times the
    area each stands for (n,)."""

    position: np.ndarray
    normal: np.ndarray
    area_albedo: np.ndarray

    @property
    def n(self) -> int:
        return int(self.position.shape[0])

    def select(self, index: slice | np.ndarray) -> SurfaceSamples:
        """The samples at ``index`` (a slice gives views, a mask copies)."""
        return SurfaceSamples(self.position[index], self.normal[index], self.area_albedo[index])


@dataclass(frozen=True)
class Binning:
    """How paths are binned and traced: ``bins`` of ``delta_t`` metres from ``t_start``;
    rays leave (or stop) ``ray_offset`` metres off a surface."""

    bins: int
    delta_t: float
    t_start: float
    ray_offset: float


@dataclass(frozen=True, eq=False)
class WallRows:
    """The wall grid by rows: x of each row (X,), y of each column (Y,), and each sensor's
    device leg (X, Y) in metres, or None when the time axis does not count the legs."""

    xs: np.ndarray
    ys: np.ndarray
    legs: np.ndarray | None = None


def laser_side(surface: SurfaceSamples, laser: np.ndarray, tracer: OcclusionTracer,
               binning: Binning, fixed_path: float = 0.0) -> tuple[LitSamples, int]:
    """The laser leg x_l -> p of every sample, keeping those the laser reaches.

    ``fixed_path`` is added to every path (the laser device leg when counted).
    Returns the lit samples and the number of occlusion rays traced.
    """
    points, normals, area_albedo = surface.position, surface.normal, surface.area_albedo
    delta_t, t_start, ray_offset = binning.delta_t, binning.t_start, binning.ray_offset
    d = laser[None, :] - points                          # p -> x_l
    r_l = np.linalg.norm(d, axis=1)
    cos_l = points[:, 2] / r_l                            # at the wall (normal +z)
    cos_in = np.einsum("ij,ij->i", normals, d) / r_l
    side = np.where(cos_in >= 0, 1.0, -1.0)
    gain = area_albedo * cos_l * np.abs(cos_in) * _INV_PI3 / r_l**2
    facing = (gain > 0) & (cos_l > 0)
    normal = normals * side[:, None]
    origin = points + ray_offset * normal
    occ = tracer.occluded(origin[facing].astype(np.float32), d[facing].astype(np.float32),
                          np.full(int(facing.sum()), _FAR, np.float32))
    lit = np.zeros(points.shape[0], bool)
    lit[np.nonzero(facing)[0][occ != 0]] = True
    p = points[lit]
    return LitSamples(
        origin=origin[lit].astype(np.float32),
        position=p.astype(np.float32),
        normal=normal[lit].astype(np.float32),
        gain=(gain[lit] * p[:, 2] / delta_t**4).astype(np.float32),
        offset=((r_l[lit] + fixed_path - t_start) / delta_t + 1.0).astype(np.float32),
    ), int(facing.sum())


class SingleSpotRows:
    """Sensor legs of one batch of lit samples, one wall-grid row at a time.

    One instance per thread: it owns its float32 work buffers. Call
    :meth:`load` with a batch of exactly ``batch`` samples, then :meth:`row`
    for each grid row this thread accumulates.
    """

    def __init__(self, wall: WallRows, batch: int, binning: Binning,
                 tracer: OcclusionTracer) -> None:
        self.xs = np.asarray(wall.xs, np.float32)
        self.ys = np.asarray(wall.ys, np.float32)
        bins, delta_t, legs = binning.bins, binning.delta_t, wall.legs
        self.bins, self.batch = bins, batch
        self.tracer = tracer
        self.inv_dt2 = np.float32(1.0 / delta_t**2)
        ny = self.ys.shape[0]
        shape = (ny, batch)
        self.r2, self.rb, self.e = (np.empty(shape, np.float32) for _ in range(3))
        # bincount is several times faster on intp indices and float64 weights than on
        # int32/float32 (its internal conversion is slow): store those types directly
        self.idx = np.empty(shape, np.intp)
        self.weight = np.empty(shape, np.float64)
        self.ay2, self.gy = np.empty(shape, np.float32), np.empty(shape, np.float32)
        self.origins = np.empty(shape + (3,), np.float32)
        self.dirs = np.empty(shape + (3,), np.float32)
        self.far = np.full(ny * batch, _FAR, np.float32)
        self.base = (np.arange(ny, dtype=np.float32) * (bins + 2))[:, None]
        # per-sensor device leg in bins, (X, Y, 1), or None when legs are not counted
        self.legs = None if legs is None else (legs / delta_t).astype(np.float32)[..., None]
        self.traced = self.free = 0
        self._batch: LitSamples | None = None

    def load(self, s: LitSamples) -> None:
        """Precompute the y-dependent terms of a batch (shared by every row)."""
        py, pz = s.position[:, 1], s.position[:, 2]
        ay = self.ys[:, None] - py[None, :]                             # (x_s - p)_y
        np.multiply(ay, ay, out=self.ay2)
        self.ay2 += pz * pz
        self.ay2 *= self.inv_dt2
        np.multiply(ay, (s.gain * s.normal[:, 1])[None, :], out=self.gy)
        self.origins[:] = s.origin[None, :, :]
        self.dirs[..., 1] = ay
        self.dirs[..., 2] = -pz[None, :]
        self._batch = s

    def row(self, ix: int, n_real: int | None = None) -> np.ndarray:
        """Row ``ix``'s paths: its histogram (Y * (bins + 2) slots) from this batch.

        ``n_real``: how many leading samples of the batch are real (the rest is
        zero-gain padding, traced but not counted in the ray statistics).
        """
        s = self._batch
        if s is None:
            raise RuntimeError("SingleSpotRows.row: load() a batch first")
        px, pz = s.position[:, 0], s.position[:, 2]
        ax = self.xs[ix] - px                                           # (x_s - p)_x
        # signed n.(x_s - p) times the sample gain: > 0 when x_s sees the lit side
        gx = s.gain * (s.normal[:, 0] * ax - s.normal[:, 2] * pz)
        r2, rb, e, idx = self.r2, self.rb, self.e, self.idx
        np.add(self.ay2, (ax * ax * self.inv_dt2)[None, :], out=r2)    # r_s^2 in bins^2
        np.sqrt(r2, out=rb)
        rb += s.offset
        if self.legs is not None:
            rb += self.legs[ix]
        np.clip(rb, 0.0, self.bins + 1, out=rb)
        rb += self.base
        np.copyto(idx, rb, casting="unsafe")                            # floor (rb >= 0)
        np.add(self.gy, gx[None, :], out=e)
        np.maximum(e, 0.0, out=e)
        np.multiply(r2, r2, out=r2)
        np.divide(e, r2, out=self.weight)                               # weight of each path
        self.dirs[..., 0] = ax
        occ = self.tracer.occluded(self.origins.reshape(-1, 3), self.dirs.reshape(-1, 3),
                                   self.far)
        flat = idx.reshape(-1)
        np.bitwise_and(flat, occ, out=flat)                             # occluded -> slot 0
        counts = np.bincount(flat, weights=self.weight.reshape(-1),
                             minlength=self.ys.shape[0] * (self.bins + 2))
        n_real = self.batch if n_real is None else n_real
        self.traced += n_real * occ.shape[0] // self.batch
        self.free += int(np.count_nonzero(occ.reshape(-1, self.batch)[:, :n_real]))
        return counts


def confocal_rows(wall: WallRows, ix: int, surface: SurfaceSamples, tracer: OcclusionTracer,
                  binning: Binning) -> tuple[np.ndarray, int, int]:
    """Confocal paths x_s -> p -> x_s of grid row ``ix`` for a batch of samples.

    One occlusion ray per pair, from the sensor towards the sample, stopping
    ``ray_offset`` short of it, serves both legs. Weight
    rho dA cos_s^2 cos_p^2 / (pi^3 r^4). Returns the row's histogram
    (Y * (bins + 2) slots), the rays traced and the rays unobstructed.
    """
    xs, ys, points, normals = wall.xs, wall.ys, surface.position, surface.normal
    bins = binning.bins
    ny, n = ys.shape[0], points.shape[0]
    sensors = np.stack([np.full(ny, xs[ix]), ys, np.zeros(ny)], axis=-1)    # (Y, 3)
    d = points[None, :, :] - sensors[:, None, :]                            # x_s -> p
    r2 = np.einsum("ijk,ijk->ij", d, d)
    r = np.sqrt(r2)
    cos_p = np.einsum("ijk,jk->ij", d, normals) / r
    weight = ((surface.area_albedo * _INV_PI3)[None, :] * (points[None, :, 2] * cos_p) ** 2
              / r2**3)
    path = 2 * r - binning.t_start
    if wall.legs is not None:
        path += wall.legs[ix][:, None]
    slot = np.clip(np.floor(path / binning.delta_t) + 1, 0, bins + 1).astype(np.int64)
    occ = tracer.occluded(np.repeat(sensors, n, axis=0).astype(np.float32),
                          d.reshape(-1, 3).astype(np.float32),
                          (1.0 - binning.ray_offset / r).reshape(-1).astype(np.float32))
    flat = (slot + (np.arange(ny) * (bins + 2))[:, None]).reshape(-1)
    flat[occ == 0] = 0
    counts = np.bincount(flat, weights=weight.reshape(-1), minlength=ny * (bins + 2))
    return counts, int(occ.shape[0]), int(np.count_nonzero(occ))

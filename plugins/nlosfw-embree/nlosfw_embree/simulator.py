"""The ``embree`` simulator: three-bounce transients with Embree visibility.

Estimator. ``samples`` points are drawn area-uniformly on every hidden triangle
(scrambled Sobol by default, see :func:`nlosfw.simulate.geometry.surface_points`); each
stands for ``total area / samples`` of surface. For every sample and every
sensor the path laser spot -> p -> sensor is weighted exactly as in
:mod:`nlosfw.simulate.physics` and binned by its length; both hidden legs are tested
with Embree occlusion rays, so surfaces shadow each other. The estimate is
unbiased for any scene and agrees in absolute value with the ``analytic``
simulator on scenes without shadowing. Point scatterers are not sampled: each
contributes its closed-form path to every sensor, times the visibility of its
two legs (also traced with Embree).

Parallelism. The wall grid is split by rows over ``threads`` Python threads
(Embree and numpy's ufuncs release the GIL); each row is accumulated by one
thread in a fixed order, so the result is bitwise the same for any number of
threads.
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from nlosfw.capture import Capture, device_legs
from nlosfw.common import available_cores
from nlosfw.simulate import (
    PointScatterers,
    Scene,
    SceneGeometry,
    Simulator,
    scene_capture,
    sobol_engine,
    surface_points,
    three_bounce,
)
from nlosfw_embree.config import EmbreeConfig
from nlosfw_embree.tracer import OcclusionTracer
from nlosfw_embree.transport import (
    Binning,
    SingleSpotRows,
    SurfaceSamples,
    WallRows,
    confocal_rows,
    laser_side,
)

log = logging.getLogger(__name__)

#: Surface samples drawn and held in memory at once (about 100 bytes each).
_CHUNK = 1 << 20


@dataclass(frozen=True, eq=False)
class _Job:
    """One render: the scene, its wall rows, how paths are binned, the tracer, the threads."""

    scene: Scene
    wall: WallRows
    binning: Binning
    tracer: OcclusionTracer
    threads: int
    fixed_leg: float = 0.0
    """The laser device leg added to every single-spot path (when the legs are counted)."""

    @property
    def hist_shape(self) -> tuple[int, int]:
        """(X, Y * (bins + 2)): per sensor, the bins plus a too-early and a too-late slot."""
        return self.wall.xs.shape[0], self.wall.ys.shape[0] * (self.binning.bins + 2)


@dataclass(frozen=True, eq=False)
class _Tally:
    """Histograms and ray statistics of part of a render; parts add up."""

    hist: np.ndarray
    rays: int = 0
    unobstructed: int = 0

    def __add__(self, other: _Tally) -> _Tally:
        return _Tally(self.hist + other.hist, self.rays + other.rays,
                      self.unobstructed + other.unobstructed)


class EmbreeSimulator(Simulator[EmbreeConfig]):
    """Monte Carlo (or randomised QMC) three-bounce transport with Embree occlusion rays."""

    config_class = EmbreeConfig

    def render(self, geometry: SceneGeometry) -> Capture:
        cfg = self.config
        start = time.perf_counter()
        scene, mesh, points = geometry.scene, geometry.mesh, geometry.points
        grid = scene.wall.grid_xyz()
        nx, ny = grid.shape[:2]
        bins = scene.time.bins
        legs = _device_legs(scene, grid)
        job = _Job(scene=scene,
                   wall=WallRows(grid[:, 0, 0], grid[0, :, 1], None if legs is None else legs[0]),
                   binning=Binning(bins, scene.time.bin_width, scene.time.start, cfg.ray_offset),
                   tracer=OcclusionTracer(mesh), threads=cfg.threads or available_cores(),
                   fixed_leg=0.0 if legs is None else legs[1])
        tally = _Tally(np.zeros(job.hist_shape))

        if mesh.n_faces:
            rng = np.random.default_rng([cfg.seed, 0x656D62])  # "emb" stream
            sobol = sobol_engine(rng) if cfg.sampler == "sobol" else None
            area = float(mesh.face_areas().sum())
            for first in range(0, cfg.samples, _CHUNK):
                n = min(_CHUNK, cfg.samples - first)
                uv = _draw(sobol, n) if sobol is not None else rng.random((n, 2))
                p, normals, albedo = surface_points(mesh, uv)
                surface = SurfaceSamples(p, normals, albedo * area / cfg.samples)
                if scene.is_confocal:
                    tally = tally + self._confocal(job, surface)
                else:
                    tally = tally + self._single_spot(job, surface)
        if points.positions.shape[0]:
            tally = tally + self._points(job, grid, points)

        H = tally.hist.reshape(nx, ny, bins + 2)[:, :, 1:-1]
        capture = scene_capture(scene, np.moveaxis(H, -1, 0))
        seconds = time.perf_counter() - start
        info = dict(capture.scene_info)
        info["render"] = {
            "simulator": "embree",
            "samples": int(cfg.samples) if mesh.n_faces else 0,
            "sampler": str(cfg.sampler),
            "threads": int(job.threads),
            "rays": int(tally.rays),
            "unobstructed_fraction": (tally.unobstructed / tally.rays
                                      if tally.rays else 1.0),
        }
        # wall-clock figures go to the log, not the capture: same scene, same bytes
        log.info("embree: %d rays in %.2f s", tally.rays, seconds)
        return capture.replace(scene_info=info)

    # ------------------------------------------------------------------ surfaces
    def _single_spot(self, job: _Job, surface: SurfaceSamples) -> _Tally:
        cfg = self.config
        lit, traced = laser_side(surface, job.scene.laser_spot_xyz(), job.tracer, job.binning,
                                 fixed_path=job.fixed_leg)
        hist = np.zeros(job.hist_shape)
        if lit.n == 0:
            return _Tally(hist, traced, 0)
        batch = min(cfg.batch, lit.n)
        real = lit.n
        lit = lit.padded(batch)
        n_rows = job.wall.xs.shape[0]
        rows = [list(range(k, n_rows, job.threads)) for k in range(min(job.threads, n_rows))]

        def work(my_rows: list[int]) -> tuple[int, int]:
            # each thread adds into its own rows of this call's histogram
            kernel = SingleSpotRows(job.wall, batch, job.binning, job.tracer)
            for b0 in range(0, lit.n, batch):
                kernel.load(lit.batch(b0, batch))
                for ix in my_rows:
                    hist[ix] += kernel.row(ix, n_real=min(batch, real - b0))
            return kernel.traced, kernel.free

        results = _run(work, rows)
        return _Tally(hist, traced + sum(r[0] for r in results),
                      real + sum(r[1] for r in results))

    def _confocal(self, job: _Job, surface: SurfaceSamples) -> _Tally:
        keep = (surface.area_albedo > 0) & (surface.position[:, 2] > 0)
        surface = surface.select(keep)
        n_cols, n_rows = job.wall.ys.shape[0], job.wall.xs.shape[0]
        batch = max(16, min(self.config.batch, (1 << 18) // max(1, n_cols)))
        rows = [list(range(k, n_rows, job.threads)) for k in range(min(job.threads, n_rows))]
        hist = np.zeros(job.hist_shape)

        def work(my_rows: list[int]) -> tuple[int, int]:
            # each thread adds into its own rows of this call's histogram
            traced = free = 0
            for b0 in range(0, surface.n, batch):
                part = surface.select(slice(b0, b0 + batch))
                for ix in my_rows:
                    counts, a, b = confocal_rows(job.wall, ix, part, job.tracer, job.binning)
                    hist[ix] += counts
                    traced, free = traced + a, free + b
            return traced, free

        results = _run(work, rows)
        return _Tally(hist, sum(r[0] for r in results), sum(r[1] for r in results))

    # ------------------------------------------------------------------ points
    def _points(self, job: _Job, grid: np.ndarray, points: PointScatterers) -> _Tally:
        """Closed-form paths of point scatterers, times the visibility of both legs."""
        scene, t = job.scene, job.scene.time
        sensors = grid.reshape(-1, 3)
        n_s = sensors.shape[0]
        laser = sensors if scene.is_confocal else scene.laser_spot_xyz()
        path, weight = three_bounce(laser, points.positions, None, points.albedo, sensors)
        if job.wall.legs is not None:
            path = path + job.wall.legs.reshape(-1)[None, :] + job.fixed_leg
        visible, rays, free = self._visible(sensors, points.positions, job.tracer)   # (P, S)
        if not scene.is_confocal:
            laser_visible, more, more_free = self._visible(scene.laser_spot_xyz()[None],
                                                           points.positions, job.tracer)
            visible &= laser_visible
            rays, free = rays + more, free + more_free
        slot = np.clip(np.floor((path - t.start) / t.bin_width) + 1, 0, t.bins + 1)
        flat = (slot.astype(np.int64) + (np.arange(n_s) * (t.bins + 2))[None, :])
        weight = np.where(visible, weight, 0.0)
        counts = np.bincount(flat.reshape(-1), weights=weight.reshape(-1),
                             minlength=int(np.prod(job.hist_shape)))
        return _Tally(counts.reshape(job.hist_shape), rays, free)

    def _visible(self, wall_points: np.ndarray, targets: np.ndarray,
                 tracer: OcclusionTracer) -> tuple[np.ndarray, int, int]:
        """(P, W) whether each target is visible from each wall point (rays stop short),
        the rays traced and the rays unobstructed."""
        d = targets[:, None, :] - wall_points[None, :, :]
        r = np.linalg.norm(d, axis=-1)
        occ = tracer.occluded(
            np.broadcast_to(wall_points[None], d.shape).reshape(-1, 3).astype(np.float32),
            d.reshape(-1, 3).astype(np.float32),
            (1.0 - self.config.ray_offset / r).reshape(-1).astype(np.float32))
        return (occ != 0).reshape(r.shape), int(occ.shape[0]), int(np.count_nonzero(occ))


def _device_legs(scene: Scene, grid: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(per-sensor leg (X, Y), fixed leg) in metres when the time axis counts device legs."""
    if not scene.capture.device_legs:
        return None
    sensors = grid.reshape(-1, 3)
    cap = scene.capture
    if scene.is_confocal:
        per = device_legs(sensors, sensors, cap.laser_position, cap.sensor_position)
        return per.reshape(grid.shape[:2]), 0.0
    spot = scene.laser_spot_xyz()
    fixed = float(np.linalg.norm(spot - np.asarray(cap.laser_position, dtype=float)))
    per = np.linalg.norm(sensors - np.asarray(cap.sensor_position, dtype=float), axis=1)
    return per.reshape(grid.shape[:2]), fixed


def _draw(engine: Any, n: int) -> np.ndarray:
    """``n`` more points of a Sobol sequence (any n is unbiased; powers of 2 balance best)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return engine.random(n)


def _run(work: Callable[[list[int]], tuple[int, int]],
         rows: list[list[int]]) -> list[tuple[int, int]]:
    """Run ``work`` on each thread's row list; the first exception propagates."""
    if len(rows) == 1:
        return [work(rows[0])]
    with ThreadPoolExecutor(max_workers=len(rows)) as pool:
        return list(pool.map(work, rows))

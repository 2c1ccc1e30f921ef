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
from dataclasses import dataclass, field
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
from nlosfw_embree.transport import SingleSpotRows, confocal_rows, laser_side

log = logging.getLogger(__name__)

#: Surface samples drawn and held in memory at once (about 100 bytes each).
_CHUNK = 1 << 20


@dataclass(frozen=True)
class _Pass:
    """One render's fixed inputs and the histogram and ray counts it accumulates into."""

    scene: Scene
    xs: np.ndarray
    """(X,) sensor x coordinates (grid rows)."""
    ys: np.ndarray
    """(Y,) sensor y coordinates."""
    tracer: OcclusionTracer
    legs: tuple[np.ndarray, float] | None
    """(per-sensor leg (X, Y), fixed leg) when the time axis counts the device legs."""
    hist: np.ndarray
    """(X, Y * (bins + 2)) histogram with an underflow and an overflow bin per sensor."""
    threads: int
    stats: dict[str, int] = field(default_factory=lambda: {"rays": 0, "unobstructed": 0})

    def run_rows(self, work: Callable[[list[int]], tuple[int, int]]) -> None:
        """Run ``work`` on the threads' interleaved grid rows and count its rays."""
        n = len(self.xs)
        rows = [list(range(k, n, self.threads)) for k in range(min(self.threads, n))]
        results = _run(work, rows)
        self.count(sum(r[0] for r in results), sum(r[1] for r in results))

    def count(self, rays: int, unobstructed: int) -> None:
        self.stats["rays"] += int(rays)
        self.stats["unobstructed"] += int(unobstructed)


class EmbreeSimulator(Simulator):
    """Monte Carlo (or randomised QMC) three-bounce transport with Embree occlusion rays."""

    config_class = EmbreeConfig

    def render(self, geometry: SceneGeometry) -> Capture:
        cfg = self.config
        start = time.perf_counter()
        scene, mesh, points = geometry.scene, geometry.mesh, geometry.points
        grid = scene.wall.grid_xyz()
        nx, ny = grid.shape[:2]
        bins = scene.time.bins
        threads = cfg.threads or available_cores()
        job = _Pass(scene, grid[:, 0, 0], grid[0, :, 1], OcclusionTracer(mesh),
                    _device_legs(scene, grid), np.zeros((nx, ny * (bins + 2))), threads)

        if mesh.n_faces:
            rng = np.random.default_rng([cfg.seed, 0x656D62])  # "emb" stream
            sobol = sobol_engine(rng) if cfg.sampler == "sobol" else None
            area = float(mesh.face_areas().sum())
            for first in range(0, cfg.samples, _CHUNK):
                n = min(_CHUNK, cfg.samples - first)
                uv = _draw(sobol, n) if sobol is not None else rng.random((n, 2))
                p, normals, albedo = surface_points(mesh, uv)
                area_albedo = albedo * area / cfg.samples
                render = self._confocal if scene.is_confocal else self._single_spot
                render(job, p, normals, area_albedo)
        if points.positions.shape[0]:
            self._points(job, grid, points)

        stats = job.stats
        H = job.hist.reshape(nx, ny, bins + 2)[:, :, 1:-1]
        capture = scene_capture(scene, np.moveaxis(H, -1, 0))
        seconds = time.perf_counter() - start
        info = dict(capture.scene_info)
        info["render"] = {
            "simulator": "embree",
            "samples": int(cfg.samples) if mesh.n_faces else 0,
            "sampler": cfg.sampler,
            "threads": int(threads),
            "rays": int(stats["rays"]),
            "unobstructed_fraction": (stats["unobstructed"] / stats["rays"]
                                      if stats["rays"] else 1.0),
            "seconds": seconds,
            "rays_per_second": stats["rays"] / seconds if seconds > 0 else 0.0,
        }
        return capture.replace(scene_info=info)

    # ------------------------------------------------------------------ surfaces
    def _single_spot(self, job: _Pass, p: np.ndarray, normals: np.ndarray,
                     area_albedo: np.ndarray) -> None:
        cfg = self.config
        t = job.scene.time
        legs = job.legs
        lit, traced = laser_side(p, normals, area_albedo, job.scene.laser_spot_xyz(), job.tracer,
                                 delta_t=t.bin_width, t_start=t.start,
                                 fixed_path=legs[1] if legs else 0.0,
                                 ray_offset=cfg.ray_offset)
        job.count(traced, lit.n)
        if lit.n == 0:
            return
        batch = min(cfg.batch, lit.n)
        real = lit.n
        lit = lit.padded(batch)

        def work(my_rows: list[int]) -> tuple[int, int]:
            kernel = SingleSpotRows(job.xs, job.ys, batch, t.bins, t.bin_width, job.tracer,
                                    legs[0] if legs else None)
            for b0 in range(0, lit.n, batch):
                kernel.load(lit.batch(b0, batch))
                for ix in my_rows:
                    kernel.row(ix, job.hist[ix], n_real=min(batch, real - b0))
            return kernel.traced, kernel.free

        job.run_rows(work)

    def _confocal(self, job: _Pass, p: np.ndarray, normals: np.ndarray,
                  area_albedo: np.ndarray) -> None:
        cfg = self.config
        t = job.scene.time
        legs = job.legs
        keep = (area_albedo > 0) & (p[:, 2] > 0)
        p, normals, area_albedo = p[keep], normals[keep], area_albedo[keep]
        batch = max(16, min(cfg.batch, (1 << 18) // max(1, len(job.ys))))

        def work(my_rows: list[int]) -> tuple[int, int]:
            traced = free = 0
            for b0 in range(0, p.shape[0], batch):
                sl = slice(b0, b0 + batch)
                for ix in my_rows:
                    a, b = confocal_rows(job.xs, job.ys, ix, p[sl], normals[sl],
                                         area_albedo[sl], job.tracer, bins=t.bins,
                                         delta_t=t.bin_width, t_start=t.start,
                                         legs=legs[0] if legs else None,
                                         ray_offset=cfg.ray_offset, out=job.hist[ix])
                    traced, free = traced + a, free + b
            return traced, free

        job.run_rows(work)

    # ------------------------------------------------------------------ points
    def _points(self, job: _Pass, grid: np.ndarray, points: PointScatterers) -> None:
        """Closed-form paths of point scatterers, times the visibility of both legs."""
        scene, legs, hist = job.scene, job.legs, job.hist
        t = scene.time
        sensors = grid.reshape(-1, 3)
        n_s = sensors.shape[0]
        laser = sensors if scene.is_confocal else scene.laser_spot_xyz()
        path, weight = three_bounce(laser, points.positions, None, points.albedo, sensors)
        if legs is not None:
            path = path + legs[0].reshape(-1)[None, :] + legs[1]
        visible = self._visible(sensors, points.positions, job)                  # (P, S)
        if not scene.is_confocal:
            visible &= self._visible(scene.laser_spot_xyz()[None], points.positions, job)
        slot = np.clip(np.floor((path - t.start) / t.bin_width) + 1, 0, t.bins + 1)
        flat = (slot.astype(np.int64) + (np.arange(n_s) * (t.bins + 2))[None, :])
        weight = np.where(visible, weight, 0.0)
        hist.reshape(-1)[:] += np.bincount(flat.reshape(-1), weights=weight.reshape(-1),
                                           minlength=hist.size)

    def _visible(self, wall_points: np.ndarray, targets: np.ndarray, job: _Pass) -> np.ndarray:
        """(P, W) whether each target is visible from each wall point (rays stop short)."""
        d = targets[:, None, :] - wall_points[None, :, :]
        r = np.linalg.norm(d, axis=-1)
        occ = job.tracer.occluded(
            np.broadcast_to(wall_points[None], d.shape).reshape(-1, 3).astype(np.float32),
            d.reshape(-1, 3).astype(np.float32),
            (1.0 - self.config.ray_offset / r).reshape(-1).astype(np.float32))
        job.count(occ.shape[0], int(np.count_nonzero(occ)))
        return (occ != 0).reshape(r.shape)


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

"""The ``analytic`` simulator: exact three-bounce transients without visibility.

Point scatterers and small Lambertian patches are evaluated in closed form
(:func:`nlosfw.simulate.physics.three_bounce`), each path placed in the bin holding its
exact length. Rectangles and heightfields are integrated by deterministic
midpoint quadrature on triangles subdivided below ``patch_size``. No ray is
traced, so nothing shadows anything: boxes and mesh files are refused, and the
result is exact only for scenes in which no surface hides another (a sampled
sight-line test, :func:`nlosfw.simulate.visibility.blocked_fraction`, logs a warning when
one does, e.g. thesis_occluded and the spikes of thesis_concave).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.config import require
from nlosfw.common.errors import ConfigError
from nlosfw.simulate.geometry import SceneGeometry, TriangleMesh
from nlosfw.simulate.interface import Simulator, SimulatorConfig, scene_capture
from nlosfw.simulate.physics import bin_index, three_bounce
from nlosfw.simulate.scene import Scene
from nlosfw.simulate.visibility import blocked_fraction

log = logging.getLogger(__name__)

SUPPORTED_TYPES = ("point", "patch", "rectangle", "heightfield")


@dataclass(frozen=True)
class AnalyticConfig(SimulatorConfig):
    """Options of the analytic simulator."""

    patch_size: float = 0.01
    """[m] Largest quadrature element for rectangles and heightfields."""
    max_pairs: int = 1_000_000
    """Element-sensor pairs evaluated at once (bounds memory to about 150 bytes per pair)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.patch_size > 0, "patch_size", f"must be > 0 metres, got {self.patch_size}")
        require(self.max_pairs >= 1, "max_pairs", f"must be >= 1, got {self.max_pairs}")


class AnalyticSimulator(Simulator[AnalyticConfig]):
    """Closed-form transients of points and patches; quadrature for planar items."""

    config_class = AnalyticConfig
    renders_lobes = True

    def render(self, geometry: SceneGeometry) -> Capture:
        scene = geometry.scene
        positions, normals, area_albedo, lobes = self.elements(geometry)
        glossy = bool(np.any(lobes > 0))
        shadowed = blocked_fraction(scene, geometry.mesh)
        if shadowed > 0:
            log.warning("analytic: %.1f%% of sampled sight lines of scene %s cross another "
                        "surface, and the analytic simulator ignores shadowing: this capture "
                        "is not physical there (use simulator=embree)", 100 * shadowed,
                        scene.name)
        sensors = scene.wall.grid_xyz().reshape(-1, 3)
        n_sensors = sensors.shape[0]
        bins = scene.time.bins
        laser = sensors if scene.is_confocal else scene.laser_spot_xyz()
        legs = scene.device_path(sensors)
        hist = np.zeros(n_sensors * bins)
        # element chunks of at least 2 x bins, so that each bincount's output (a block of
        # sensors x bins) is smaller than its input (elements x the same sensors)
        per_chunk = min(positions.shape[0], max(2 * bins, 1024))
        block = max(1, self.config.max_pairs // max(per_chunk, 1))
        has_normal = ~np.isnan(normals[:, 0])
        for start in range(0, positions.shape[0], per_chunk):
            sl = slice(start, start + per_chunk)
            surface = has_normal[sl]
            groups = [(m, n, k) for m, n, k in (
                (surface, normals[sl][surface], lobes[sl][surface] if glossy else None),
                (~surface, None, None)) if m.any()]
            for s0 in range(0, n_sensors, block):
                s1 = min(n_sensors, s0 + block)
                las = laser[s0:s1] if scene.is_confocal else laser
                for mask, nrm, lob in groups:
                    path, weight = three_bounce(las, positions[sl][mask], nrm,
                                                area_albedo[sl][mask], sensors[s0:s1], lobe=lob)
                    idx = bin_index(path + legs[None, s0:s1], scene.time.start,
                                    scene.time.bin_width)
                    ok = (idx >= 0) & (idx < bins) & (weight > 0)
                    local = np.broadcast_to(np.arange(s1 - s0), idx.shape)[ok] * bins + idx[ok]
                    hist[s0 * bins:s1 * bins] += np.bincount(local, weights=weight[ok],
                                                             minlength=(s1 - s0) * bins)
        H = hist.reshape(scene.wall.resolution[0], scene.wall.resolution[1], bins)
        return scene_capture(scene, np.moveaxis(H, -1, 0))

    def check_scene(self, scene: Scene) -> None:
        """Only items without self-shadowing and with a closed form or quadrature."""
        for i, item in enumerate(scene.geometry):
            if item.type not in SUPPORTED_TYPES:
                raise ConfigError(f"scene.geometry[{i}].type",
                                  f"the analytic simulator has no visibility and supports only "
                                  f"{', '.join(SUPPORTED_TYPES)}; got {item.type!r} (use a "
                                  "ray-tracing simulator such as embree)")

    def elements(self, geometry: SceneGeometry
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Quadrature elements: positions (E, 3), normals (E, 3; NaN for points), rho*dA (E,)
        and lobe exponents (E,; 0 for points and Lambertian items)."""
        scene = geometry.scene
        points = geometry.points
        pos = [points.positions]
        nrm = [np.full_like(points.positions, np.nan)]
        area = [points.albedo]
        lobe = [np.zeros(points.positions.shape[0])]
        for i, item in enumerate(scene.geometry):
            if item.type == "point":
                continue
            mesh = geometry.mesh.item_mesh(i)
            if item.type == "patch":
                normal = mesh.face_normals()[0]
                p, n = np.asarray(item.position, dtype=float)[None], normal[None]
                a = np.array([item.albedo * mesh.face_areas().sum()])
            else:
                p, n, a = _midpoint_quadrature(mesh, self.config.patch_size)
            pos.append(p)
            nrm.append(n)
            area.append(a)
            lobe.append(np.full(a.shape[0], float(item.lobe)))
        return (np.concatenate(pos), np.concatenate(nrm), np.concatenate(area),
                np.concatenate(lobe))

def _midpoint_quadrature(mesh: TriangleMesh, size: float) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """Centroids, normals and rho*area of each triangle split into k^2 similar sub-triangles."""
    tris = mesh.triangles()
    normals = mesh.face_normals()
    areas = mesh.face_areas()
    edges = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max(axis=1)
    out_p, out_n, out_a = [], [], []
    for k in np.unique(np.maximum(1, np.ceil(edges / size)).astype(int)):
        sel = np.nonzero(np.maximum(1, np.ceil(edges / size)).astype(int) == k)[0]
        bary = _subtriangle_centroids(int(k))                          # (k^2, 3)
        t = tris[sel]                                                  # (T, 3, 3)
        p = np.einsum("sc,tcd->tsd", bary, t).reshape(-1, 3)
        out_p.append(p)
        out_n.append(np.repeat(normals[sel], bary.shape[0], axis=0))
        out_a.append(np.repeat(mesh.albedo[sel] * areas[sel] / bary.shape[0], bary.shape[0]))
    return np.concatenate(out_p), np.concatenate(out_n), np.concatenate(out_a)


def _subtriangle_centroids(k: int) -> np.ndarray:
    """Barycentric centroids of the k^2 congruent sub-triangles of a triangle."""
    cents = []
    for i in range(k):
        for j in range(k - i):
            cents.append(((i + 1 / 3) / k, (j + 1 / 3) / k))          # upright
            if i + j < k - 1:
                cents.append(((i + 2 / 3) / k, (j + 2 / 3) / k))      # inverted
    uv = np.array(cents)
    return np.column_stack([1 - uv.sum(1), uv[:, 0], uv[:, 1]])

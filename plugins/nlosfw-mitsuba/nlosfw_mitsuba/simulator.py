"""The ``mitsuba`` simulator: Mitsuba 3 + mitransient's ``transient_nlos_path``.

The scene becomes a Mitsuba scene: the relay wall is a diffuse ``rectangle``
(albedo 1) carrying an ``nlos_capture_meter`` sensor at the sensor device with a
``transient_hdr_film`` of the wall's resolution and time axis; the laser is a
narrow ``projector`` at the laser device aimed at the spot; every hidden item is
a triangle mesh with a two-sided diffuse BSDF of its albedo, built from the very
triangles :mod:`nlosfw.simulate.geometry` gives every simulator. The integrator uses laser
sampling, hidden-geometry sampling (optional), a box temporal filter, keeps only
the configured bounce order, and counts the device legs in the time axis exactly
when the scene does.

Conventions, checked against :mod:`nlosfw.simulate.physics` by the tests:

* mitransient's transient is [y, x, t, channel]; nlosfw's H is [t, x, y].
* Its values are nlosfw's times ``pi cos(theta_l) / d_l^2`` for a projector of unit
  irradiance, d_l the distance from the laser device to the spot and theta_l the
  angle there between the wall normal and the laser; that factor is divided out,
  per sensor for confocal scans, so the capture follows nlosfw's radiometric
  convention (unit power at the spot) exactly.
* mitransient starts rays off a surface by Mitsuba's ray epsilon (about 0.1 mm):
  rays aimed near the edge of a small surface from far, oblique wall points then
  miss it, so small patches come out slightly dark (about 0.5% for a 4 cm patch
  seen at 60 degrees, negligible for surfaces of 20 cm and more).
* Hidden-geometry sampling only aims at surfaces whose front faces a wall point,
  so open surfaces are oriented towards the wall and closed meshes outwards.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from nlosfw.capture import Capture
from nlosfw.common import ConfigError, PluginError, one_line
from nlosfw.simulate import (
    Scene,
    SceneGeometry,
    Simulator,
    TriangleMesh,
    sample_surface,
    scene_capture,
)
from nlosfw_mitsuba.config import MitsubaConfig
from nlosfw_mitsuba.llvm import configure_llvm

log = logging.getLogger(__name__)

#: Paths per rendering pass when ``spp_per_pass`` is automatic (mitransient's own limit;
#: Dr.Jit's memory hardly depends on it: 0.55 GB peak at 64 x 64 x 2048 bins).
_PATHS_PER_PASS = 1 << 26
#: Full opening angle of the laser projector (degrees).
_LASER_FOV = 0.2


def load_mitsuba(variant: str) -> Any:
    """Import mitsuba with a working LLVM, select ``variant`` and register mitransient."""
    llvm = configure_llvm()
    try:
        import mitsuba as mi
    except ImportError as err:
        raise PluginError(f"mitsuba simulator: cannot import mitsuba ({err}); run: pip install "
                          "mitsuba mitransient") from None
    try:
        mi.set_variant(variant)
    except Exception as err:  # drjit raises several types when its LLVM backend fails
        raise PluginError(f"mitsuba simulator: variant {variant} is unavailable "
                          f"({one_line(err)}; "
                          f"LLVM: {llvm or 'unset'}); install LLVM >= 16 with `apt-get install "
                          "-y libllvm19` or set DRJIT_LIBLLVM_PATH") from None
    try:
        import mitransient  # noqa: F401  (registers its plugins with mitsuba)
    except ImportError as err:
        raise PluginError(f"mitsuba simulator: cannot import mitransient ({err}); run: pip "
                          "install mitransient") from None
    return mi


class MitsubaSimulator(Simulator[MitsubaConfig]):
    """Transient path tracing with Mitsuba 3 and mitransient, in nlosfw's conventions."""

    config_class = MitsubaConfig

    def check_scene(self, scene: Scene) -> None:
        """Point scatterers have no area for Mitsuba to intersect: refuse them."""
        for i, item in enumerate(scene.geometry):
            if item.type == "point":
                raise ConfigError(f"scene.geometry[{i}].type", (
                    "the mitsuba simulator cannot render point scatterers (they have no "
                    "area); use a small patch, or the analytic or embree simulator"))

    def render(self, geometry: SceneGeometry) -> Capture:
        cfg = self.config
        start = time.perf_counter()
        scene = geometry.scene
        mi = load_mitsuba(str(cfg.variant))
        import drjit as dr

        if cfg.threads:
            dr.set_thread_count(cfg.threads)
        meshes = [_oriented(geometry.mesh.item_mesh(i), item.type)
                  for i, item in enumerate(scene.geometry)]
        mi_scene = _build_scene(mi, scene, meshes, cfg)
        _check_device_sight_lines(mi, mi_scene, scene)
        blocked = _blocked_fraction(mi, mi_scene, scene, meshes) \
            if cfg.hidden_geometry_sampling else 0.0
        if blocked > 1e-3:
            log.warning("mitsuba: %.1f%% of the sight lines from the wall to hidden surfaces "
                        "facing it cross another surface first; mitransient's hidden-geometry "
                        "sampling counts that light twice. Set hidden_geometry_sampling=false "
                        "(unbiased, slow) or use the embree simulator.", 100 * blocked)

        nx, ny = scene.wall.resolution
        per_pass = cfg.spp_per_pass or max(1, _PATHS_PER_PASS // (nx * ny))
        integrator = mi_scene.integrator()
        total = np.zeros((scene.time.bins, nx, ny))
        passes = 0
        for first in range(0, cfg.spp, per_pass):
            spp = min(per_pass, cfg.spp - first)
            seed = (cfg.seed * 7919 + passes) % (1 << 32)
            _, transient = integrator.render(mi_scene, seed=seed, spp=spp)
            block = np.array(transient, dtype=np.float64)     # [y, x, t, channel]
            total += (spp / cfg.spp) * np.transpose(block.mean(axis=-1), (2, 1, 0))
            passes += 1
        H = total / _laser_factor(scene)[None]
        capture = scene_capture(scene, H)
        seconds = time.perf_counter() - start
        info = dict(capture.scene_info)
        info["render"] = {
            "simulator": "mitsuba",
            "variant": str(cfg.variant),
            "spp": int(cfg.spp),
            "passes": passes,
            "paths": int(cfg.spp) * nx * ny,
            "hidden_geometry_sampling": cfg.hidden_geometry_sampling,
            "blocked_sight_line_fraction": float(blocked),
        }
        # wall-clock figures go to the log, not the capture: same scene, same bytes
        log.info("mitsuba: %d paths in %.2f s", int(cfg.spp) * nx * ny, seconds)
        return capture.replace(scene_info=info)


# --------------------------------------------------------------------------- scene
def _build_scene(mi: Any, scene: Scene, meshes: list[TriangleMesh], cfg: MitsubaConfig) -> Any:
    """The Mitsuba scene of an nlosfw scene (see the module docstring)."""
    wall, cap, t = scene.wall, scene.capture, scene.time
    nx, ny = wall.resolution
    centre = [wall.center[0], wall.center[1], 0.0]
    target = centre if scene.is_confocal else scene.laser_spot_xyz().tolist()
    laser = [float(v) for v in cap.laser_position]
    direction = np.subtract(target, laser)
    up = [0.0, 1.0, 0.0] if abs(direction[1]) < 0.99 * np.linalg.norm(direction) \
        else [1.0, 0.0, 0.0]
    T = mi.ScalarTransform4f
    desc: dict[str, Any] = {
        "type": "scene",
        "integrator": {
            "type": "transient_nlos_path",
            "nlos_laser_sampling": True,
            "nlos_hidden_geometry_sampling": cfg.hidden_geometry_sampling,
            "nlos_hidden_geometry_sampling_includes_relay_wall": False,
            "temporal_filter": "box",
            # mitransient counts bounces without the final wall point: its 2 is our 3
            "filter_bounces": cfg.bounces - 1 if cfg.bounces > 0 else -1,
            "max_depth": cfg.max_bounces,
            "account_first_and_last_bounces": bool(cap.device_legs),
            "capture_type": "confocal" if scene.is_confocal else "single",
        },
        "laser": {
            "type": "projector",
            "irradiance": 1.0,
            "fov": _LASER_FOV,
            "to_world": T().look_at(origin=laser, target=[float(v) for v in target], up=up),
        },
        "relay_wall": {
            "type": "rectangle",
            "to_world": T().translate(centre).scale([wall.size[0] / 2, wall.size[1] / 2, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": 1.0},
            "sensor": {
                "type": "nlos_capture_meter",
                "sensor_origin": [float(v) for v in cap.sensor_position],
                "sampler": {"type": str(cfg.sampler), "sample_count": 1},
                "film": {
                    "type": "transient_hdr_film",
                    "width": nx,
                    "height": ny,
                    "temporal_bins": t.bins,
                    "bin_width_opl": t.bin_width,
                    "start_opl": t.start,
                    "rfilter": {"type": "box"},
                },
            },
        },
    }
    for i, mesh in enumerate(meshes):
        desc[f"item_{i:04d}"] = _mesh(mi, f"item_{i:04d}", mesh, float(mesh.albedo[0]))
    level = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)  # mitransient warns spuriously about filter_bounces
    try:
        return mi.load_dict(desc)
    finally:
        mi.set_log_level(level)


def _mesh(mi: Any, name: str, mesh: TriangleMesh, albedo: float) -> Any:
    """A Mitsuba mesh of the triangles with a two-sided diffuse BSDF."""
    import drjit as dr

    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided",
                                  "bsdf": {"type": "diffuse", "reflectance": albedo}})
    out = mi.Mesh(name, mesh.vertices.shape[0], mesh.n_faces, props=props)
    params = mi.traverse(out)
    params["vertex_positions"] = dr.ravel(mi.Point3f(mesh.vertices.T.astype(np.float32)))
    params["faces"] = dr.ravel(mi.Vector3u(mesh.faces.T.astype(np.uint32)))
    params.update()
    return out


def _oriented(mesh: TriangleMesh, item_type: str) -> TriangleMesh:
    """Open surfaces facing the wall (normal z < 0); closed meshes with outward normals."""
    faces = mesh.faces.copy()
    if item_type == "box" or (item_type == "mesh" and _is_closed(faces)):
        tri = mesh.triangles()
        volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
        if volume < 0:
            faces = faces[:, ::-1]
    else:
        flip = mesh.face_normals()[:, 2] > 0
        faces[flip] = faces[flip][:, ::-1]
    return TriangleMesh(mesh.vertices, np.ascontiguousarray(faces), mesh.albedo, mesh.item)


def _is_closed(faces: np.ndarray) -> bool:
    """Whether every edge is shared by exactly two faces."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def _laser_factor(scene: Scene) -> np.ndarray:
    """mitransient / nlosfw per sensor, (X, Y): pi cos(theta_l) / d_l^2 at each laser point."""
    grid = scene.wall.grid_xyz()
    spots = grid if scene.is_confocal else scene.laser_spot_xyz()[None, None, :]
    d = np.asarray(scene.capture.laser_position, dtype=float) - spots
    dist = np.linalg.norm(d, axis=-1)
    factor = np.pi * (d[..., 2] / dist) / dist**2
    return np.broadcast_to(factor, grid.shape[:2])


# --------------------------------------------------------------------------- checks
def _check_device_sight_lines(mi: Any, mi_scene: Any, scene: Scene) -> None:
    """Mitsuba traces the device legs: hidden geometry must not block them."""
    grid = scene.wall.grid_xyz().reshape(-1, 3)
    spots = grid if scene.is_confocal else scene.laser_spot_xyz()[None, :]
    for option, device, targets in (("sensor_position", scene.capture.sensor_position, grid),
                                    ("laser_position", scene.capture.laser_position, spots)):
        origin = np.broadcast_to(np.asarray(device, dtype=float), targets.shape)
        blocked = _blocked(mi, mi_scene, origin, targets)
        if blocked.any():
            raise ConfigError(f"scene.capture.{option}", (
                f"hidden geometry blocks the line of sight from the device to "
                f"{int(blocked.sum())} wall point(s); mitsuba traces the device legs: move "
                "the device or the geometry"))


def _blocked_fraction(mi: Any, mi_scene: Any, scene: Scene,
                      meshes: list[TriangleMesh]) -> float:
    """Fraction of (wall point, facing surface point) sight lines that hit something first."""
    mesh = TriangleMesh.concatenate(meshes)
    if mesh.n_faces == 0:
        return 0.0
    points, normals, _, _ = sample_surface(mesh, 256, np.random.default_rng(0))
    grid = scene.wall.grid_xyz()
    step = (max(1, grid.shape[0] // 8), max(1, grid.shape[1] // 8))
    wall = grid[:: step[0], :: step[1]].reshape(-1, 3)
    origin = np.repeat(wall, points.shape[0], axis=0)
    target = np.tile(points, (wall.shape[0], 1))
    facing = np.einsum("ij,ij->i", np.tile(normals, (wall.shape[0], 1)), origin - target) > 0
    if not facing.any():
        return 0.0
    return float(_blocked(mi, mi_scene, origin[facing], target[facing], shorten=1e-3).mean())


def _blocked(mi: Any, mi_scene: Any, origins: np.ndarray, targets: np.ndarray,
             shorten: float = 1e-4) -> np.ndarray:
    """Whether each segment origin -> target (stopped ``shorten`` m short) hits a surface."""
    d = targets - origins
    dist = np.linalg.norm(d, axis=1)
    d = d / dist[:, None]
    ray = mi.Ray3f(mi.Point3f(*origins.T.astype(np.float32)),
                   mi.Vector3f(*d.T.astype(np.float32)))
    start = 1e-4                                      # leave the surface the ray starts on
    ray.o = ray.o + ray.d * start
    ray.maxt = mi.Float((dist - start - shorten).astype(np.float32))
    return np.asarray(mi_scene.ray_test(ray), dtype=bool)

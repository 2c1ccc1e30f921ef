"""Hidden-scene geometry: triangle meshes from scene items, surface sampling, ground truth.

Every simulator renders the same triangles, built here from a
:class:`~nlosfw.simulate.Scene`, so two simulators can only disagree about light
transport, never about shapes.
"""

from __future__ import annotations

import dataclasses
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nlosfw.common.errors import ConfigError
from nlosfw.simulate.scene import GeometryItem, Scene

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """Triangles with a diffuse albedo and the index of their scene item, per face."""

    vertices: np.ndarray
    """(V, 3) float64."""
    faces: np.ndarray
    """(F, 3) int64 indices into vertices; counter-clockwise around the normal."""
    albedo: np.ndarray
    """(F,) diffuse albedo."""
    item: np.ndarray
    """(F,) index of the scene item each face comes from."""

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def triangles(self) -> np.ndarray:
        """(F, 3, 3) corner coordinates."""
        return self.vertices[self.faces]

    def face_normals(self) -> np.ndarray:
        """(F, 3) unit normals."""
        t = self.triangles()
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    def face_areas(self) -> np.ndarray:
        t = self.triangles()
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)

    def item_mesh(self, index: int) -> TriangleMesh:
        """The triangles of scene item ``index`` alone (vertices compacted)."""
        faces = self.faces[self.item == index]
        used, inverse = np.unique(faces, return_inverse=True)
        return TriangleMesh(self.vertices[used], inverse.reshape(faces.shape),
                            self.albedo[self.item == index], self.item[self.item == index])

    @staticmethod
    def concatenate(meshes: list[TriangleMesh]) -> TriangleMesh:
        if not meshes:
            return TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0),
                                np.zeros(0, np.int64))
        offsets = np.cumsum([0] + [m.vertices.shape[0] for m in meshes[:-1]])
        return TriangleMesh(
            vertices=np.concatenate([m.vertices for m in meshes]),
            faces=np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=False)]),
            albedo=np.concatenate([m.albedo for m in meshes]),
            item=np.concatenate([m.item for m in meshes]),
        )


@dataclass(frozen=True, eq=False)
class PointScatterers:
    """Isotropic point scatterers (only the ``point`` items of a scene)."""

    positions: np.ndarray
    """(P, 3)."""
    albedo: np.ndarray
    """(P,) effective scattering area in m^2 (see :mod:`nlosfw.simulate.physics`)."""
    item: np.ndarray
    """(P,) scene item index."""


def rotation_matrix(degrees_xyz: tuple[float, float, float]) -> np.ndarray:
    """Rotation about x, then y, then z (angles in degrees): ``Rz @ Ry @ Rx``."""
    ax, ay, az = np.radians(degrees_xyz)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def item_mesh(item: GeometryItem, index: int = 0, base_dir: Path | None = None) -> TriangleMesh:
    """Triangles of one item in world coordinates (not for ``point`` items)."""
    where = f"scene.geometry[{index}]"
    if item.type in ("rectangle", "patch"):
        verts, faces = _rectangle(item.size[0], item.size[1])
    elif item.type == "box":
        verts, faces = _box(*item.size)
    elif item.type == "heightfield":
        verts, faces = _heightfield(item, where)
    elif item.type == "mesh":
        verts, faces = _load_mesh_file(item, where, base_dir)
    else:
        raise ConfigError(f"{where}.type", f"{item.type!r} has no triangles")
    rot = rotation_matrix(item.rotation)
    world = verts @ rot.T + np.asarray(item.position, dtype=float)
    n = faces.shape[0]
    return TriangleMesh(world, faces.astype(np.int64), np.full(n, float(item.albedo)),
                        np.full(n, index, dtype=np.int64))


def scene_mesh(scene: Scene, base_dir: Path | None = None) -> TriangleMesh:
    """All triangles of a scene (every item except points), validated to lie beyond the wall."""
    meshes = [item_mesh(item, i, base_dir) for i, item in enumerate(scene.geometry)
              if item.type != "point"]
    mesh = TriangleMesh.concatenate(meshes)
    for i, item in enumerate(scene.geometry):
        if item.type == "point":
            continue
        zmin = float(mesh.vertices[mesh.faces[mesh.item == i]][..., 2].min())
        if zmin <= 0:
            raise ConfigError(f"scene.geometry[{i}]",
                              f"{item.type} reaches z = {zmin:.3g} m; hidden geometry must lie "
                              "in front of the wall (z > 0)")
    return mesh


def scene_points(scene: Scene) -> PointScatterers:
    """The point scatterers of a scene, validated to lie beyond the wall."""
    idx = [i for i, item in enumerate(scene.geometry) if item.type == "point"]
    pos = np.array([scene.geometry[i].position for i in idx], dtype=float).reshape(-1, 3)
    for i, p in zip(idx, pos, strict=False):
        if p[2] <= 0:
            raise ConfigError(f"scene.geometry[{i}].position",
                              f"z = {p[2]:.3g} m; hidden geometry must lie in front of the wall "
                              "(z > 0)")
    return PointScatterers(pos, np.array([scene.geometry[i].albedo for i in idx], dtype=float),
                           np.array(idx, dtype=np.int64))


def surface_points(mesh: TriangleMesh, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """Map unit-square samples ``uv`` (n, 2) to area-uniform points on the mesh.

    ``u`` picks a triangle through the cumulative area and is reused, rescaled
    to [0, 1), as the first coordinate inside it; ``(u', v)`` is then warped to
    the triangle by the square-root map. The map is continuous inside each
    triangle, so stratified or low-discrepancy ``uv`` give spatially stratified
    points. Returns (points, face normals, albedo), each with n rows.
    """
    uv = np.asarray(uv, dtype=float)
    if mesh.n_faces == 0 or uv.shape[0] == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    areas = mesh.face_areas()
    cdf = np.cumsum(areas)
    cdf /= cdf[-1]
    lower = np.concatenate([[0.0], cdf[:-1]])
    u = uv[:, 0]
    tri = np.minimum(np.searchsorted(cdf, u, side="right"), mesh.n_faces - 1)
    width = np.maximum(cdf[tri] - lower[tri], 1e-300)
    r1 = np.clip((u - lower[tri]) / width, 0.0, 1.0)
    r2 = uv[:, 1]
    s = np.sqrt(r1)
    b1, b2 = s * (1 - r2), s * r2
    v = mesh.vertices
    f = mesh.faces[tri]
    a = v[f[:, 0]]
    points = a + b1[:, None] * (v[f[:, 1]] - a) + b2[:, None] * (v[f[:, 2]] - a)
    return points, mesh.face_normals()[tri], mesh.albedo[tri]


def unit_square_samples(n: int, rng: np.random.Generator, stratified: bool = True) -> np.ndarray:
    """``n`` points in [0, 1)^2: scrambled Sobol (randomised QMC) or independent uniform.

    Both are unbiased (every point is uniformly distributed); scrambled Sobol
    points are stratified at every scale and converge much faster.
    """
    if n <= 0:
        return np.zeros((0, 2))
    if not stratified:
        return rng.random((n, 2))
    engine = sobol_engine(rng)
    with warnings.catch_warnings():  # balance is best for powers of two; any n is unbiased
        warnings.simplefilter("ignore", UserWarning)
        return engine.random(n)


def sobol_engine(rng: np.random.Generator, dims: int = 2) -> Any:
    """A scrambled Sobol engine in ``dims`` dimensions seeded from ``rng`` (``.random(n)``)."""
    from scipy.stats import qmc

    try:
        return qmc.Sobol(dims, scramble=True, rng=rng)
    except TypeError:  # scipy < 1.15 names the argument seed
        return qmc.Sobol(dims, scramble=True, seed=rng)


def sample_surface(mesh: TriangleMesh, n: int, rng: np.random.Generator,
                   stratified: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``n`` area-uniform samples on the mesh: (points, normals, albedo, area per sample).

    With ``stratified`` the samples come from a scrambled Sobol sequence mapped by
    :func:`surface_points` (unbiased, far lower variance than independent
    sampling); otherwise they are independent.
    """
    if mesh.n_faces == 0 or n <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), 0.0
    points, normals, albedo = surface_points(mesh, unit_square_samples(n, rng, stratified))
    return points, normals, albedo, float(mesh.face_areas().sum()) / n


@dataclass(frozen=True, eq=False)
class SceneGeometry:
    """A validated scene with its hidden geometry built once."""

    scene: Scene
    """The scene, with mesh file paths made absolute."""
    mesh: TriangleMesh
    """Every triangle of the scene (all items but points)."""
    points: PointScatterers
    """The point scatterers."""
    path_range: tuple[float, float]
    """Conservative bounds (m) on the optical path of every three-bounce path, device legs
    included when the time axis counts them."""


def resolve_mesh_paths(scene: Scene, base_dir: Path | None = None) -> Scene:
    """The scene with every mesh path made absolute (relative to ``base_dir`` or the cwd)."""
    base = Path.cwd() if base_dir is None else Path(base_dir)
    items = []
    changed = False
    for item in scene.geometry:
        if item.type == "mesh" and item.path:
            path = Path(item.path).expanduser()
            if not path.is_absolute():
                item = dataclasses.replace(item, path=str((base / path).resolve()))
                changed = True
        items.append(item)
    return dataclasses.replace(scene, geometry=tuple(items)) if changed else scene


def validate_scene(scene: Scene, base_dir: Path | None = None) -> SceneGeometry:
    """Build and check a scene's hidden geometry before anything is rendered.

    One-line :class:`ConfigError` naming the item for: a missing, empty or
    unreadable mesh file; geometry at or behind the wall (z <= 0); a time
    window that cannot hold any path of the scene (the shortest and longest
    possible paths are bounded from the items' bounding boxes, the wall grid
    and, when counted, the device legs). A window that cuts off part of the
    paths is allowed and logged as a warning.
    """
    scene = resolve_mesh_paths(scene, base_dir)
    mesh = scene_mesh(scene)
    points = scene_points(scene)
    lo, hi = path_length_range(scene, mesh, points)
    t = scene.time
    if hi < t.start or lo >= t.end:
        legs = "with" if scene.capture.device_legs else "without"
        raise ConfigError("scene.time", (
            f"the window [{t.start:.4g}, {t.end:.4g}) m (start + bins * bin_width) holds no path "
            f"of this scene: its paths ({legs} device legs) lie within [{lo:.4g}, {hi:.4g}] m; "
            f"valid: start < {hi:.4g} and start + bins * bin_width > {lo:.4g}"))
    if lo < t.start or hi > t.end:
        approx = _sampled_path_range(scene, mesh, points)
        if approx[0] < t.start or approx[1] > t.end:
            log.warning("scene %s: paths span about [%.3f, %.3f] m but the time window is "
                        "[%.3f, %.3f) m; paths outside it are not recorded",
                        scene.name, approx[0], approx[1], t.start, t.end)
    return SceneGeometry(scene=scene, mesh=mesh, points=points, path_range=(lo, hi))


def path_length_range(scene: Scene, mesh: TriangleMesh,
                      points: PointScatterers) -> tuple[float, float]:
    """Bounds (lo, hi) in metres on the optical path of every laser -> hidden -> sensor path.

    Each item is enclosed in its bounding box: the shortest path to a box is at
    least the distance from the laser point to the box plus the distance from
    the box to the sensor point, the longest at most the largest sum over the
    box corners (the path length is convex in the hidden point). Device legs are
    added when the time axis counts them.
    """
    sensors = scene.wall.grid_xyz().reshape(-1, 3)
    lasers = sensors if scene.is_confocal else np.broadcast_to(scene.laser_spot_xyz(),
                                                               sensors.shape)
    legs = scene.device_path(sensors)
    boxes = []
    for i in np.unique(mesh.item):
        corners = mesh.vertices[mesh.faces[mesh.item == i]].reshape(-1, 3)
        boxes.append((corners.min(axis=0), corners.max(axis=0)))
    boxes += [(p, p) for p in points.positions]
    lo, hi = np.inf, -np.inf
    for bmin, bmax in boxes:
        near = (_box_distance(lasers, bmin, bmax) + _box_distance(sensors, bmin, bmax) + legs)
        corners = np.array([[x, y, z] for x in (bmin[0], bmax[0]) for y in (bmin[1], bmax[1])
                            for z in (bmin[2], bmax[2])])
        far = (np.linalg.norm(lasers[:, None] - corners[None], axis=-1)
               + np.linalg.norm(sensors[:, None] - corners[None], axis=-1)).max(axis=1) + legs
        lo, hi = min(lo, float(near.min())), max(hi, float(far.max()))
    return lo, hi


def _box_distance(points: np.ndarray, bmin: np.ndarray, bmax: np.ndarray) -> np.ndarray:
    """Euclidean distance from each point (N, 3) to an axis-aligned box."""
    gap = np.maximum(np.maximum(bmin - points, points - bmax), 0.0)
    return np.linalg.norm(gap, axis=-1)


def _sampled_path_range(scene: Scene, mesh: TriangleMesh, points: PointScatterers,
                        n: int = 512) -> tuple[float, float]:
    """Approximate (min, max) optical path over surface samples, vertices and a sparse grid."""
    from nlosfw.simulate.physics import three_bounce

    cloud = [points.positions]
    if mesh.n_faces:
        cloud.append(sample_surface(mesh, n, np.random.default_rng(0))[0])
        cloud.append(mesh.vertices[:: max(1, mesh.vertices.shape[0] // n)])
    cloud_pts = np.concatenate(cloud)
    grid = scene.wall.grid_xyz()
    step = (max(1, grid.shape[0] // 16), max(1, grid.shape[1] // 16))
    sub = np.concatenate([grid[:: step[0], :: step[1]].reshape(-1, 3),
                          grid[[0, 0, -1, -1], [0, -1, 0, -1]]])
    laser = sub if scene.is_confocal else scene.laser_spot_xyz()
    path, _ = three_bounce(laser, cloud_pts, None, np.ones(cloud_pts.shape[0]), sub)
    path = path + scene.device_path(sub)[None, :]
    return float(path.min()), float(path.max())


def _rectangle(w: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[-w / 2, -h / 2, 0], [-w / 2, h / 2, 0], [w / 2, h / 2, 0], [w / 2, -h / 2, 0]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])  # normal -z: facing the wall


def _box(w: float, h: float, d: float) -> tuple[np.ndarray, np.ndarray]:
    x, y, z = w / 2, h / 2, d / 2
    v = np.array([[sx * x, sy * y, sz * z] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    # faces with outward normals; vertex index = 4*(sx>0) + 2*(sy>0) + (sz>0)
    quads = [(0, 2, 6, 4), (1, 5, 7, 3), (0, 4, 5, 1), (2, 3, 7, 6), (0, 1, 3, 2), (4, 6, 7, 5)]
    faces = []
    for a, b, c, e in quads:
        faces += [[a, b, c], [a, c, e]]
    return v, np.array(faces)


def _heightfield(item: GeometryItem, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle displaced towards (+height) or away from (-height) the wall by bumps.

    ``params``: ``resolution`` (vertices per side, default 65) and ``bumps``, a list
    of ``{x, y, radius, height, shape}`` in the rectangle's local metres with
    ``shape`` ``gaussian`` (default) or ``cone``.
    """
    params = dict(item.params)
    res = int(params.pop("resolution", 65))
    bumps = params.pop("bumps", [])
    if params:
        raise ConfigError(f"{where}.params.{sorted(params)[0]}",
                          "unknown heightfield parameter; valid: resolution, bumps")
    if res < 2:
        raise ConfigError(f"{where}.params.resolution", f"must be >= 2, got {res}")
    w, h = item.size
    xs, ys = np.linspace(-w / 2, w / 2, res), np.linspace(-h / 2, h / 2, res)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    gz = np.zeros_like(gx)
    for k, bump in enumerate(bumps):
        try:
            bx, by = float(bump["x"]), float(bump["y"])
            radius, height = float(bump["radius"]), float(bump["height"])
            shape = bump.get("shape", "gaussian")
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"{where}.params.bumps[{k}]",
                              "needs numbers x, y, radius, height (and optional shape)") from None
        r = np.hypot(gx - bx, gy - by)
        if shape == "gaussian":
            gz -= height * np.exp(-0.5 * (r / radius) ** 2)
        elif shape == "cone":
            gz -= height * np.clip(1 - r / radius, 0, None)
        else:
            raise ConfigError(f"{where}.params.bumps[{k}].shape",
                              f"{shape!r} is not valid; valid: gaussian, cone")
    verts = np.stack([gx, gy, gz], axis=-1).reshape(-1, 3)
    idx = np.arange(res * res).reshape(res, res)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces


def _load_mesh_file(item: GeometryItem, where: str,
                    base_dir: Path | None) -> tuple[np.ndarray, np.ndarray]:
    path = Path(item.path or "").expanduser()
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    if not path.is_file():
        raise ConfigError(f"{where}.path", f"mesh file not found: {path}")
    if path.stat().st_size == 0:
        raise ConfigError(f"{where}.path", f"mesh file is empty: {path}")
    import trimesh  # light (numpy-only); imported here so the core starts fast

    try:
        loaded = trimesh.load(str(path), force="mesh")
    except Exception as err:  # trimesh raises many types for bad files
        raise ConfigError(f"{where}.path", f"cannot read mesh {path}: {err}") from None
    verts = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if faces.size == 0 or verts.size == 0:
        raise ConfigError(f"{where}.path", f"mesh file has no triangles: {path}")
    centre = (verts.min(axis=0) + verts.max(axis=0)) / 2
    return (verts - centre) * item.scale, faces

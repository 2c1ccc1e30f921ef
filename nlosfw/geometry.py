"""Hidden-scene geometry: triangle meshes from scene items, surface sampling, ground truth.

Every simulator renders the same triangles, built here from a
:class:`~nlosfw.scene.Scene`, so two simulators can only disagree about light
transport, never about shapes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlosfw.errors import ConfigError
from nlosfw.scene import GeometryItem, Scene

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
    """(P,) effective scattering area in m^2 (see :mod:`nlosfw.physics`)."""
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


def sample_surface(mesh: TriangleMesh, n: int, rng: np.random.Generator,
                   stratified: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``n`` area-uniform samples on the mesh: (points, normals, albedo, area per sample).

    With ``stratified`` the triangle choice uses one jittered sample per 1/n of
    the cumulative area (unbiased, lower variance than independent sampling).
    """
    if mesh.n_faces == 0 or n <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), 0.0
    areas = mesh.face_areas()
    total = float(areas.sum())
    cdf = np.cumsum(areas) / total
    u = (np.arange(n) + rng.random(n)) / n if stratified else rng.random(n)
    tri = np.minimum(np.searchsorted(cdf, u, side="right"), mesh.n_faces - 1)
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    b0, b1, b2 = 1 - s, s * (1 - r2), s * r2
    t = mesh.triangles()[tri]
    points = b0[:, None] * t[:, 0] + b1[:, None] * t[:, 1] + b2[:, None] * t[:, 2]
    return points, mesh.face_normals()[tri], mesh.albedo[tri], total / n


def ground_truth_maps(mesh: TriangleMesh, grid_xyz: np.ndarray,
                      chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Depth and albedo seen from the wall along +z at ``grid_xyz`` (X, Y, 3).

    Returns ``(depth, albedo)`` with shape (X, Y): depth is the distance from
    the wall to the first surface hit, -1 where nothing is hit (as in y-tal),
    and albedo is 0 there.
    """
    shape = grid_xyz.shape[:-1]
    xy = grid_xyz.reshape(-1, 3)[:, :2]
    depth = np.full(xy.shape[0], np.inf)
    albedo = np.zeros(xy.shape[0])
    tris = mesh.triangles()
    for start in range(0, mesh.n_faces, chunk):
        t = tris[start:start + chunk]
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        lo, hi = t[..., :2].min(axis=1), t[..., :2].max(axis=1)
        inside_box = np.all((xy[:, None] >= lo[None] - 1e-12) & (xy[:, None] <= hi[None] + 1e-12),
                            axis=2)
        ray_i, tri_i = np.nonzero(inside_box)
        if ray_i.size == 0:
            continue
        p = xy[ray_i]
        a2, b2, c2 = a[tri_i, :2], b[tri_i, :2], c[tri_i, :2]
        v0, v1, v2 = b2 - a2, c2 - a2, p - a2
        den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
        ok = np.abs(den) > 1e-15
        den = np.where(ok, den, 1.0)
        w1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
        w2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
        hit = ok & (w1 >= -1e-9) & (w2 >= -1e-9) & (w1 + w2 <= 1 + 1e-9)
        z = a[tri_i, 2] + w1 * (b[tri_i, 2] - a[tri_i, 2]) + w2 * (c[tri_i, 2] - a[tri_i, 2])
        ray_i, z, face = ray_i[hit], z[hit], tri_i[hit] + start
        order = np.lexsort((z, ray_i))  # nearest hit first for each ray
        ray_i, z, face = ray_i[order], z[order], face[order]
        first = np.r_[True, ray_i[1:] != ray_i[:-1]]
        ray_i, z, face = ray_i[first], z[first], face[first]
        closer = z < depth[ray_i]
        depth[ray_i[closer]] = z[closer]
        albedo[ray_i[closer]] = mesh.albedo[face[closer]]
    depth[~np.isfinite(depth)] = -1.0
    return depth.reshape(shape), albedo.reshape(shape)


def representative_points(scene: Scene, mesh: TriangleMesh, n: int = 4096,
                          seed: int = 0) -> np.ndarray:
    """Vertices, surface samples and point scatterers: a cloud spanning the hidden geometry."""
    pts = [mesh.vertices, scene_points(scene).positions]
    if mesh.n_faces:
        pts.append(sample_surface(mesh, n, np.random.default_rng(seed))[0])
    return np.concatenate(pts)


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

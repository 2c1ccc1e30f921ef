"""Rays against a scene's hidden meshes: the first surface each ray meets, the ground truth
seen from the wall, and how much of the scene shadows itself (trimesh, with Embree when
the embree plugin has installed embreex)."""

from __future__ import annotations

import numpy as np

from nlosfw.simulate.geometry import TriangleMesh, sample_surface, scene_points
from nlosfw.simulate.scene import Scene


def first_hits(mesh: TriangleMesh, origins: np.ndarray, directions: np.ndarray,
               inclusive_edges: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(face, distance) of the first triangle each ray (N, 3) meets, (N,) each.

    ``face`` is -1 and ``distance`` inf where a ray meets nothing. Rays are cast
    through trimesh's ray interface: by default with Embree when embreex is
    installed (float32 traversal, hit points recomputed in float64; watertight,
    so a ray exactly on an edge that two triangles share hits one of them, but one
    exactly on a surface's outer edge may miss), else with trimesh's float64 numpy
    code. ``inclusive_edges`` always uses the numpy code, which counts a ray
    through any edge or corner (within 1e-12 barycentric) as a hit: the same
    answer on every install, for maps that must not depend on what is installed.
    """
    origins = np.asarray(origins, dtype=float)
    directions = np.asarray(directions, dtype=float)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    face = np.full(origins.shape[0], -1, dtype=np.int64)
    distance = np.full(origins.shape[0], np.inf)
    if mesh.n_faces == 0 or origins.shape[0] == 0:
        return face, distance
    import trimesh  # here, not at the top: importing trimesh imports embreex when installed

    rays = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False, validate=False,
                           use_embree=not inclusive_edges).ray
    location, ray, tri = rays.intersects_location(origins, directions, multiple_hits=False)
    location = np.asarray(location, dtype=float).reshape(-1, 3)     # (0,) when nothing is hit
    ray = np.asarray(ray, dtype=np.int64)
    face[ray] = tri
    distance[ray] = np.einsum("ij,ij->i", location - origins[ray], directions[ray])
    return face, distance


def ground_truth_maps(mesh: TriangleMesh,
                      grid_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth and albedo seen from the wall along +z at ``grid_xyz`` (X, Y, 3).

    Returns ``(depth, albedo)`` with shape (X, Y): depth is the distance from
    the wall to the first surface hit, -1 where nothing is hit (as in y-tal),
    and albedo is 0 there. A ray through a triangle's edge or corner hits it,
    also on a surface's outer boundary, on every install (``inclusive_edges``).
    """
    origins = np.asarray(grid_xyz, dtype=float).reshape(-1, 3)
    directions = np.broadcast_to(np.array([0.0, 0.0, 1.0]), origins.shape)
    face, distance = first_hits(mesh, origins, directions, inclusive_edges=True)
    hit = face >= 0
    depth = np.where(hit, distance, -1.0)
    albedo = np.zeros(origins.shape[0])
    albedo[hit] = mesh.albedo[face[hit]]
    shape = np.shape(grid_xyz)[:-1]
    return depth.reshape(shape), albedo.reshape(shape)


def blocked_fraction(scene: Scene, mesh: TriangleMesh, points_per_item: int = 48,
                     wall_points: int = 4) -> float:
    """Fraction of sampled sight lines from the wall to the hidden surfaces that cross a surface.

    Segments join a ``wall_points`` x ``wall_points`` grid of wall points and the
    laser spot to ``points_per_item`` area-uniform samples of every item (and to
    point scatterers); a segment is blocked when its first hit (:func:`first_hits`)
    lies more than a micrometre before its end, so a segment that ends on a
    surface is not. 0 means no shadowing was found.
    """
    grid = scene.wall.grid_xyz()
    ix = np.linspace(0, grid.shape[0] - 1, wall_points).round().astype(int)
    iy = np.linspace(0, grid.shape[1] - 1, wall_points).round().astype(int)
    starts = np.concatenate([grid[np.ix_(ix, iy)].reshape(-1, 3), scene.laser_spot_xyz()[None]])
    rng = np.random.default_rng(0)
    ends = [scene_points(scene).positions]
    for i in np.unique(mesh.item):
        sub = TriangleMesh(mesh.vertices, mesh.faces[mesh.item == i],
                           mesh.albedo[mesh.item == i], mesh.item[mesh.item == i])
        ends.append(sample_surface(sub, points_per_item, rng)[0])
    end = np.concatenate(ends)
    if mesh.n_faces == 0 or end.shape[0] == 0:
        return 0.0
    origin = np.repeat(starts, end.shape[0], axis=0)
    d = np.tile(end, (starts.shape[0], 1)) - origin
    length = np.linalg.norm(d, axis=1)
    _, distance = first_hits(mesh, origin, d)
    return float(np.mean(distance < length - 1e-6))

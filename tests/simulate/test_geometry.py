"""Hidden geometry: triangles of scene items, surface sampling, validation, ground truth."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from nlosfw.capture.geometry import device_legs
from nlosfw.common.errors import ConfigError
from nlosfw.simulate.geometry import (
    TriangleMesh,
    item_mesh,
    path_length_range,
    rotation_matrix,
    sample_surface,
    scene_mesh,
    surface_points,
    unit_square_samples,
    validate_scene,
)
from nlosfw.simulate.physics import three_bounce
from nlosfw.simulate.scene import GeometryItem, scene_from_config
from nlosfw.simulate.visibility import ground_truth_maps
from nlosfw.testing.fixtures import tiny_scene_config


def scene(geometry, **changes):
    config = tiny_scene_config()
    config["geometry"] = geometry
    for key, value in changes.items():
        config[key] = {**config.get(key, {}), **value}
    return scene_from_config(config)


def test_rotation_is_rz_ry_rx_and_orthonormal():
    r = rotation_matrix((90.0, 0.0, 0.0))
    np.testing.assert_allclose(r @ [0, 1, 0], [0, 0, 1], atol=1e-12)     # x rotates y to z
    r = rotation_matrix((30.0, -50.0, 70.0))
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    rx, ry, rz = (rotation_matrix(a) for a in ((30, 0, 0), (0, -50, 0), (0, 0, 70)))
    np.testing.assert_allclose(r, rz @ ry @ rx, atol=1e-12)


def test_rectangle_faces_the_wall_and_has_its_area():
    mesh = item_mesh(GeometryItem(type="rectangle", position=(0.1, 0.2, 0.7), size=(0.3, 0.5)))
    np.testing.assert_allclose(mesh.face_normals(), [[0, 0, -1]] * 2, atol=1e-12)
    assert mesh.face_areas().sum() == pytest.approx(0.15)
    np.testing.assert_allclose(mesh.vertices.mean(axis=0), [0.1, 0.2, 0.7])


def test_box_is_closed_with_outward_normals():
    mesh = item_mesh(GeometryItem(type="box", position=(0, 0, 1), size=(0.2, 0.3, 0.4)))
    tri = mesh.triangles()
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert volume == pytest.approx(0.2 * 0.3 * 0.4)          # positive: outward normals
    assert mesh.face_areas().sum() == pytest.approx(2 * (0.06 + 0.08 + 0.12))
    centres = tri.mean(axis=1) - [0, 0, 1]
    assert np.all(np.einsum("ij,ij->i", centres, mesh.face_normals()) > 0)


def test_heightfield_bumps_point_towards_or_away_from_the_wall():
    item = GeometryItem(type="heightfield", position=(0, 0, 1), size=(1, 1), params={
        "resolution": 41, "bumps": [{"x": -0.25, "y": 0, "radius": 0.1, "height": 0.2,
                                     "shape": "cone"},
                                    {"x": 0.25, "y": 0, "radius": 0.1, "height": -0.15}]})
    z = item_mesh(item).vertices[:, 2]
    assert z.min() == pytest.approx(0.8)                     # spike tip towards the wall
    assert z.max() == pytest.approx(1.15)                    # dent away from it
    bad = GeometryItem(type="heightfield", size=(1, 1), params={"bumps": [{"x": 0}]})
    with pytest.raises(ConfigError, match=r"params\.bumps\[0\]"):
        item_mesh(bad)
    with pytest.raises(ConfigError, match=r"params\.colour"):
        item_mesh(GeometryItem(type="heightfield", size=(1, 1), params={"colour": 1}))


def test_surface_points_are_area_uniform_and_on_their_triangles():
    # two triangles of areas 1/8 and 3/8 (a trapezoid split by a diagonal)
    vertices = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 0.25, 1.0]])
    mesh = TriangleMesh(vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.ones(2), np.zeros(2, int))
    areas = mesh.face_areas()
    uv = unit_square_samples(1 << 14, np.random.default_rng(0))
    points, normals, _ = surface_points(mesh, uv)
    in_first = _inside(points, vertices[[0, 1, 2]])
    assert np.all(in_first | _inside(points, vertices[[0, 2, 3]]))
    assert in_first.mean() == pytest.approx(areas[0] / areas.sum(), abs=1e-3)
    # uniform density inside a triangle: the centroid of the samples is the centroid
    np.testing.assert_allclose(points[in_first].mean(axis=0), vertices[[0, 1, 2]].mean(axis=0),
                               atol=2e-3)


def _inside(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = tri[:, :2]
    q = p[:, :2]

    def side(u, v):
        return (v[0] - u[0]) * (q[:, 1] - u[1]) - (v[1] - u[1]) * (q[:, 0] - u[0])

    s = np.stack([side(a, b), side(b, c), side(c, a)])
    return np.all(s >= -1e-12, axis=0) | np.all(s <= 1e-12, axis=0)


def test_sobol_sampling_is_unbiased_and_converges_faster():
    mesh = item_mesh(GeometryItem(type="rectangle", position=(0, 0, 1), size=(1, 1),
                                  rotation=(20, 0, 0)))
    exact = 1.0 / 12 + 0.0   # integral of x^2 over [-1/2, 1/2]^2 (x is unchanged by rotation)
    errors = {}
    for stratified in (True, False):
        est = [np.mean(sample_surface(mesh, 1024, np.random.default_rng(s), stratified)[0][:, 0]
                       ** 2) for s in range(20)]
        assert np.mean(est) == pytest.approx(exact, rel=0.02)
        errors[stratified] = np.sqrt(np.mean((np.array(est) - exact) ** 2))
    assert errors[True] < 0.2 * errors[False]


def test_geometry_at_or_behind_the_wall_is_refused():
    with pytest.raises(ConfigError, match=r"scene\.geometry\[1\]: rectangle reaches z = "):
        validate_scene(scene([{"type": "patch", "position": [0, 0, 0.5]},
                              {"type": "rectangle", "position": [0, 0, 0.1], "size": [1, 1],
                               "rotation": [40, 0, 0]}]))
    with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.position"):
        validate_scene(scene([{"type": "point", "position": [0, 0, 0.0]}]))


def test_time_window_without_any_path_is_refused_with_the_path_range():
    with pytest.raises(ConfigError, match=r"^scene\.time: the window \[5, 5\.64\) m") as err:
        validate_scene(scene([{"type": "patch"}], time={"start": 5.0, "bins": 64}))
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match=r"scene\.time"):
        validate_scene(scene([{"type": "patch"}], time={"start": 0.0, "bins": 10}))


def test_partial_window_is_allowed_with_a_warning(caplog):
    with caplog.at_level(logging.WARNING, logger="nlosfw.simulate.geometry"):
        validate_scene(scene([{"type": "patch"}], time={"start": 2.2, "bins": 40}))
    assert "paths outside it are not recorded" in caplog.text


@pytest.mark.parametrize("capture", [{}, {"type": "confocal"}, {"device_legs": True},
                                     {"type": "confocal", "device_legs": True}])
def test_path_range_bounds_every_path(capture):
    s = scene([{"type": "rectangle", "position": [0.2, -0.1, 0.7], "size": [0.4, 0.3],
                "rotation": [0, 30, 0]}, {"type": "point", "position": [-0.3, 0.2, 0.4]}],
              capture=capture)
    geometry = validate_scene(s)
    lo, hi = path_length_range(s, geometry.mesh, geometry.points)
    points = np.concatenate([sample_surface(geometry.mesh, 4096, np.random.default_rng(0))[0],
                             geometry.mesh.vertices, geometry.points.positions])
    sensors = s.wall.grid_xyz().reshape(-1, 3)
    laser = sensors if s.is_confocal else s.laser_spot_xyz()
    path, _ = three_bounce(laser, points, None, np.ones(points.shape[0]), sensors)
    if s.capture.device_legs:
        path += device_legs(laser, sensors, s.capture.laser_position,
                            s.capture.sensor_position)[None]
    assert lo <= path.min() and path.max() <= hi + 1e-9
    assert hi - path.max() < 0.3 and path.min() - lo < 0.3        # and the bounds are tight


def test_mesh_paths_resolve_against_base_dir(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]]).export(
        tmp_path / "tri.stl")
    s = scene([{"type": "mesh", "path": "tri.stl", "position": [0, 0, 0.5]}])
    geometry = validate_scene(s, base_dir=tmp_path)
    assert geometry.scene.geometry[0].path == str((tmp_path / "tri.stl").resolve())
    assert geometry.mesh.n_faces == 1
    with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.path: mesh file not found"):
        validate_scene(s)
    (tmp_path / "empty.obj").write_text("")
    with pytest.raises(ConfigError, match=r"mesh file is empty"):
        validate_scene(scene([{"type": "mesh", "path": str(tmp_path / "empty.obj")}]))


def test_ground_truth_sees_the_nearest_surface():
    s = scene([{"type": "rectangle", "position": [-0.1, 0, 0.5], "size": [0.4, 0.4],
                "albedo": 0.5},
               {"type": "rectangle", "position": [0.1, 0, 0.8], "size": [0.6, 0.6]}])
    grid = s.wall.grid_xyz()
    depth, albedo = ground_truth_maps(scene_mesh(s), grid)
    x, y = grid[..., 0], grid[..., 1]
    front = (np.abs(x + 0.1) < 0.2) & (np.abs(y) < 0.2)
    back = ~front & (np.abs(x - 0.1) < 0.3) & (np.abs(y) < 0.3)
    np.testing.assert_allclose(depth[front], 0.5)
    np.testing.assert_allclose(albedo[front], 0.5)
    np.testing.assert_allclose(depth[back], 0.8)
    assert np.all(depth[~front & ~back] == -1) and np.all(albedo[~front & ~back] == 0)


def test_blocked_fraction_finds_shadowing_only_where_it_exists():
    from nlosfw.simulate.builtin_scenes import builtin_scene
    from nlosfw.simulate.visibility import blocked_fraction

    for name, shadowed in (("thesis_two_planes", False), ("thesis_planes", False),
                           ("thesis_occluded", True), ("thesis_concave", True)):
        s = builtin_scene(name)
        assert (blocked_fraction(s, scene_mesh(s)) > 0) == shadowed, name


# --------------------------------------------------------------------------- ray casting
def _ray_code(request, monkeypatch):
    """'embree' (skipped without embreex) or 'numpy': the trimesh ray code the test uses."""
    trimesh = pytest.importorskip("trimesh")
    if request.param == "embree" and not trimesh.ray.has_embree:
        pytest.skip("embreex is not installed")
    if request.param == "numpy":
        monkeypatch.setattr(trimesh.ray, "has_embree", False)
    return request.param


@pytest.fixture(params=["embree", "numpy"])
def ray_code(request, monkeypatch):
    return _ray_code(request, monkeypatch)


def _grid(xs, ys, z=0.0):
    x, y = np.meshgrid(np.asarray(xs, float), np.asarray(ys, float), indexing="ij")
    return np.stack([x, y, np.full_like(x, z)], axis=-1)


def test_ground_truth_counts_rays_through_edges_and_corners():
    """Rays exactly on shared and outer edges and on corners of a square hit it."""
    square = item_mesh(GeometryItem(type="rectangle", position=(0.0, 0.0, 0.5), size=(0.4, 0.4),
                                    albedo=0.3))
    assert square.n_faces == 2                    # two triangles sharing a diagonal
    corners = square.vertices[:, :2]
    on_edges = np.array([[-0.2, -0.2], [0.2, 0.2], [0.0, 0.0], [0.1, 0.1], [-0.2, 0.05],
                         [0.2, -0.1], [0.0, 0.2], [0.1, -0.2]])
    outside = np.array([[0.2 + 1e-7, 0.0], [0.0, -0.2 - 1e-7], [0.3, 0.3]])
    points = np.concatenate([corners, on_edges, outside])
    grid = np.concatenate([points, np.zeros((points.shape[0], 1))], axis=1)[:, None, :]
    depth, albedo = ground_truth_maps(square, grid)
    inside = np.arange(points.shape[0]) < corners.shape[0] + on_edges.shape[0]
    np.testing.assert_allclose(depth[inside, 0], 0.5, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(albedo[inside, 0], 0.3)
    assert np.all(depth[~inside] == -1) and np.all(albedo[~inside] == 0)


def test_ground_truth_through_the_vertices_of_a_curved_surface():
    """Rays through the shared vertices of a heightfield see the vertex heights exactly."""
    mesh = item_mesh(GeometryItem(type="heightfield", position=(0, 0, 0.6), size=(0.4, 0.4),
                                  params={"resolution": 9, "bumps": [
                                      {"x": -0.05, "y": 0.05, "radius": 0.1, "height": 0.1,
                                       "shape": "cone"},
                                      {"x": 0.1, "y": -0.1, "radius": 0.08, "height": -0.05}]}))
    assert np.ptp(mesh.vertices[:, 2]) > 0.05
    vertices = mesh.vertices[np.unique(mesh.faces)]
    grid = np.concatenate([vertices[:, :2], np.zeros((vertices.shape[0], 1))], 1)[:, None]
    depth, _ = ground_truth_maps(mesh, grid)
    np.testing.assert_allclose(depth[:, 0], vertices[:, 2], rtol=0, atol=1e-12)


def test_first_hits_find_the_nearest_of_stacked_surfaces(ray_code):
    """Listed back to front, overlapping, one tilted: each ray reports the nearest."""
    from nlosfw.simulate.visibility import first_hits

    items = [{"type": "rectangle", "position": [0.0, 0.0, 0.9], "size": [0.8, 0.8],
              "albedo": 0.1},
             {"type": "rectangle", "position": [0.1, 0.0, 0.7], "size": [0.4, 0.4],
              "albedo": 0.2},
             {"type": "rectangle", "position": [-0.1, 0.0, 0.5], "size": [0.2, 0.2],
              "rotation": [0.0, 30.0, 0.0], "albedo": 0.3}]
    mesh = scene_mesh(scene(items))
    origins = _grid(np.linspace(-0.387, 0.387, 27), np.linspace(-0.383, 0.383, 23)).reshape(-1, 3)
    face, distance = first_hits(mesh, origins, np.tile([0.0, 0.0, 1.0], (origins.shape[0], 1)))
    x, y = origins[:, 0], origins[:, 1]
    # the tilted square (rotated about y) spans x = -0.1 +- 0.1 cos 30, z = 0.5 -+ x' sin 30
    tilted = (np.abs(x + 0.1) < 0.1 * np.cos(np.pi / 6) - 1e-9) & (np.abs(y) < 0.1 - 1e-9)
    middle = ~tilted & (np.abs(x - 0.1) < 0.2) & (np.abs(y) < 0.2)
    back = ~tilted & ~middle
    assert tilted.sum() > 10 and middle.sum() > 10 and back.sum() > 10
    expected_z = 0.5 - (x + 0.1) * np.tan(np.pi / 6)        # + x' (towards +x) moves to -z
    np.testing.assert_allclose(distance[tilted], expected_z[tilted], rtol=0, atol=1e-12)
    np.testing.assert_allclose(distance[middle], 0.7, rtol=0, atol=1e-12)
    np.testing.assert_allclose(distance[back], 0.9, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(mesh.albedo[face[tilted]], 0.3)
    np.testing.assert_array_equal(mesh.albedo[face[middle]], 0.2)
    np.testing.assert_array_equal(mesh.albedo[face[back]], 0.1)
    # rays through the shared diagonals and the corners of the back square hit it once
    corners = mesh.vertices[np.unique(mesh.faces[mesh.item == 0])]
    diagonal = np.array([[0.35, 0.35, 0.0], [-0.3, -0.3, 0.0], [0.25, -0.25, 0.0]])
    probes = np.concatenate([diagonal, corners * [0.999, 0.999, 0.0]])
    face, distance = first_hits(mesh, probes, np.tile([0.0, 0.0, 1.0], (probes.shape[0], 1)))
    assert np.all(face >= 0)
    np.testing.assert_allclose(distance, 0.9, rtol=0, atol=1e-12)


@pytest.mark.parametrize("gap, expected", [(2e-6, 0.5), (2e-7, 0.0)])
def test_segments_ending_on_a_surface_are_not_blocked(ray_code, gap, expected):
    """Two equal squares ``gap`` apart: sight lines to the back one cross the front one.

    Half of the sampled segments end on the front square (never blocked), half on
    the back one: blocked when the front square lies more than the last micrometre
    of the segment (gap / cos > 1e-6 for every segment here) before its end.
    """
    from nlosfw.simulate.visibility import blocked_fraction

    items = [{"type": "rectangle", "position": [0.0, 0.0, 0.5], "size": [0.3, 0.3]},
             {"type": "rectangle", "position": [0.0, 0.0, 0.5 - gap], "size": [0.3, 0.3]}]
    s = scene(items)
    assert blocked_fraction(s, scene_mesh(s)) == expected


def test_blocked_fraction_is_the_same_with_either_ray_code(monkeypatch):
    trimesh = pytest.importorskip("trimesh")
    if not trimesh.ray.has_embree:
        pytest.skip("embreex is not installed")
    from nlosfw.simulate.builtin_scenes import builtin_scene
    from nlosfw.simulate.visibility import blocked_fraction

    scenes = [builtin_scene(n) for n in ("thesis_occluded", "thesis_concave", "thesis_planes")]
    embree = [blocked_fraction(s, scene_mesh(s)) for s in scenes]
    monkeypatch.setattr(trimesh.ray, "has_embree", False)
    assert [blocked_fraction(s, scene_mesh(s)) for s in scenes] == embree


def test_rays_that_meet_nothing(ray_code):
    from nlosfw.simulate.visibility import first_hits

    mesh = scene_mesh(scene([{"type": "rectangle", "position": [0.0, 0.0, 0.5],
                              "size": [0.2, 0.2]}]))
    origins = np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 0.0]])
    face, distance = first_hits(mesh, origins, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))
    assert face.tolist() == [-1, -1] and np.all(np.isinf(distance))
    depth, albedo = ground_truth_maps(mesh, origins[:1, None])
    assert depth.tolist() == [[-1.0]] and albedo.tolist() == [[0.0]]
    empty = TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0),
                         np.zeros(0, np.int64))
    assert ground_truth_maps(empty, origins[:, None])[0].tolist() == [[-1.0], [-1.0]]

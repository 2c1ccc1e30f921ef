"""Hidden geometry: triangles of scene items, surface sampling, validation, ground truth."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from nlosfw.capture.geometry import device_legs
from nlosfw.common.errors import ConfigError
from nlosfw.simulate.geometry import (
    TriangleMesh,
    ground_truth_maps,
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
    from nlosfw.simulate.geometry import blocked_fraction

    for name, shadowed in (("thesis_two_planes", False), ("thesis_planes", False),
                           ("thesis_occluded", True), ("thesis_concave", True)):
        s = builtin_scene(name)
        assert (blocked_fraction(s, scene_mesh(s)) > 0) == shadowed, name

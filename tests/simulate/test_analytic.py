"""The analytic simulator and nlosfw.simulate.physics against closed forms written out here."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from nlosfw.common.errors import ConfigError
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.physics import three_bounce
from nlosfw.testing.fixtures import analytic_agreement, relative_l2, rendered
from nlosfw.testing.fixtures import scene_with as kit_scene_with


def scene_with(geometry, **capture):
    return kit_scene_with(geometry, resolution=(6, 5), **capture)


@pytest.mark.parametrize("capture", [{}, {"type": "confocal"}, {"device_legs": True}])
def test_point_scatterer_closed_form(capture):
    p = np.array([0.15, -0.1, 0.55])
    area = 0.003
    scene = scene_with([{"type": "point", "position": p.tolist(), "albedo": area}], **capture)
    H = rendered(AnalyticSimulator(), scene).H
    sensors = scene.wall.grid_xyz()
    dt = scene.time.bin_width
    laser_dev = np.asarray(scene.capture.laser_position)
    sensor_dev = np.asarray(scene.capture.sensor_position)
    for ix in range(sensors.shape[0]):
        for iy in range(sensors.shape[1]):
            s = sensors[ix, iy]
            spot = s if scene.is_confocal else np.zeros(3)
            r_l, r_s = np.linalg.norm(p - spot), np.linalg.norm(p - s)
            # rho dA cos_l cos_s / (pi^3 r_l^2 r_s^2): no cosines at a point scatterer
            weight = area * (p[2] / r_l) * (p[2] / r_s) / (np.pi**3 * r_l**2 * r_s**2)
            path = r_l + r_s
            if scene.capture.device_legs:
                path += np.linalg.norm(spot - laser_dev) + np.linalg.norm(s - sensor_dev)
            profile = H[:, ix, iy]
            assert np.count_nonzero(profile) == 1
            assert int(np.argmax(profile)) == int(np.floor(path / dt))
            assert profile.max() == pytest.approx(weight, rel=1e-6)


def test_three_bounce_is_reciprocal_two_sided_and_one_sided_for_opposite_sides():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.3, 0.3, (40, 3)) + [0, 0, 0.8]
    normals = rng.normal(size=(40, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    a, b = np.array([0.2, -0.1, 0.0]), np.array([-0.4, 0.3, 0.0])
    area = rng.random(40)
    path_ab, w_ab = three_bounce(a, pts, normals, area, b[None])
    path_ba, w_ba = three_bounce(b, pts, normals, area, a[None])
    np.testing.assert_allclose(w_ab, w_ba, rtol=1e-12)
    np.testing.assert_allclose(path_ab, path_ba, rtol=1e-12)
    _, w_flip = three_bounce(a, pts, -normals, area, b[None])
    np.testing.assert_allclose(w_ab, w_flip, rtol=1e-12)
    side_a = np.sign(np.einsum("ij,ij->i", normals, a - pts))
    side_b = np.sign(np.einsum("ij,ij->i", normals, b - pts))
    assert np.all(w_ab[side_a != side_b] == 0) and np.all(w_ab[side_a == side_b] > 0)


def test_rectangle_energy_matches_adaptive_quadrature():
    """Total energy at one sensor against scipy's dblquad of the same integrand."""
    centre, w, h = np.array([0.1, -0.05, 0.6]), 0.3, 0.2
    scene = scene_with([{"type": "rectangle", "position": centre.tolist(), "size": [w, h]}])
    H = rendered(AnalyticSimulator({"patch_size": 0.005}), scene).H
    sensor = scene.wall.grid_xyz()[1, 3]

    def f(y, x):
        p = centre + [x, y, 0]
        r_l, r_s = np.linalg.norm(p), np.linalg.norm(p - sensor)
        cos = p[2] ** 2 / (r_l * r_s)               # cos_in = cos_l, cos_out = cos_s here
        return cos * cos / (np.pi**3 * r_l**2 * r_s**2)

    exact, _ = integrate.dblquad(f, -w / 2, w / 2, -h / 2, h / 2, epsabs=0, epsrel=1e-9)
    assert H[:, 1, 3].sum() == pytest.approx(exact, rel=1e-4)


def test_quadrature_converges_as_patches_shrink():
    scene = scene_with([{"type": "rectangle", "position": [0.1, -0.05, 0.6], "size": [0.3, 0.2],
                         "rotation": [10, -20, 5]},
                        {"type": "heightfield", "position": [-0.2, 0.1, 0.9], "size": [0.3, 0.3],
                         "params": {"resolution": 9,
                                    "bumps": [{"x": 0, "y": 0, "radius": 0.08,
                                               "height": -0.05}]}}])
    coarse = rendered(AnalyticSimulator({"patch_size": 0.02}), scene).H.astype(float)
    fine = rendered(AnalyticSimulator({"patch_size": 0.004}), scene).H.astype(float)
    assert coarse.sum() / fine.sum() == pytest.approx(1.0, abs=2e-3)
    smooth = np.cumsum(coarse, axis=0) - np.cumsum(fine, axis=0)   # compare arrival curves
    assert np.abs(smooth).max() < 0.01 * fine.sum(axis=0).max()


def test_items_needing_visibility_are_refused():
    for item in ({"type": "box", "size": [0.1, 0.1, 0.1]}, {"type": "mesh", "path": "x.obj"}):
        with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.type: .*embree"):
            AnalyticSimulator().check_scene(scene_with([{"position": [0, 0, 0.5], **item}]))
    box = scene_with([{"position": [0, 0, 0.5], "type": "box", "size": [0.1, 0.1, 0.1]}])
    with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.type: .*embree"):
        AnalyticSimulator().simulate(box)


def test_shadowing_scenes_are_flagged(caplog):
    import logging

    from nlosfw.simulate.builtin_scenes import builtin_scene

    small = {"wall": {"resolution": [4, 4]}, "time": {"bins": 256, "bin_width": 0.024}}
    with caplog.at_level(logging.WARNING, logger="nlosfw.simulate.analytic"):
        rendered(AnalyticSimulator({"patch_size": 0.05}),
                 builtin_scene("thesis_two_planes", **small))
    assert "ignores shadowing" not in caplog.text
    with caplog.at_level(logging.WARNING, logger="nlosfw.simulate.analytic"):
        rendered(AnalyticSimulator({"patch_size": 0.05}),
                 builtin_scene("thesis_occluded", **small))
    assert "ignores shadowing" in caplog.text


@pytest.mark.parametrize("confocal", [False, True])
def test_three_bounce_matches_the_formula_term_by_term(confocal):
    """The vectorised physics against the docstring formula evaluated pair by pair."""
    rng = np.random.default_rng(2)
    pts = rng.uniform(-0.5, 0.5, (12, 3)) + [0, 0, 0.9]
    normals = rng.normal(size=(12, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    area = rng.random(12)
    sensors = np.c_[rng.uniform(-1, 1, (9, 2)), np.zeros(9)]
    laser = sensors if confocal else np.array([0.1, -0.2, 0.0])
    path, weight = three_bounce(laser, pts, normals, area, sensors)
    for i, p in enumerate(pts):
        for j, s in enumerate(sensors):
            x_l = laser[j] if confocal else laser
            r_l, r_s = np.linalg.norm(x_l - p), np.linalg.norm(s - p)
            cos_l, cos_s = p[2] / r_l, p[2] / r_s
            cos_in, cos_out = normals[i] @ (x_l - p) / r_l, normals[i] @ (s - p) / r_s
            same_side = cos_in * cos_out > 0
            expected = (area[i] * cos_l * abs(cos_in) * abs(cos_out) * cos_s
                        / (np.pi**3 * r_l**2 * r_s**2)) if same_side else 0.0
            assert weight[i, j] == pytest.approx(expected, rel=1e-12, abs=1e-300)
            assert path[i, j] == pytest.approx(r_l + r_s, rel=1e-12)


# --------------------------------------------------------------------------- the kit's helpers
class _Scaled(AnalyticSimulator):
    """The analytic transient times 2, but sensor (0, 0) times 3: known disagreements."""

    def render(self, geometry):
        capture = super().render(geometry)
        H = 2.0 * np.asarray(capture.H, dtype=float)
        H[:, 0, 0] *= 1.5
        return capture.replace(H=H.astype(capture.H.dtype))


def test_analytic_agreement_reports_known_disagreements():
    scene = scene_with([{"type": "rectangle", "position": [0.1, -0.05, 0.6], "size": [0.3, 0.2],
                         "rotation": [10.0, -20.0, 5.0]}])
    same = analytic_agreement(AnalyticSimulator({"patch_size": 0.003}), scene)
    assert same == (1.0, 0.0, 0.0)
    H = rendered(AnalyticSimulator({"patch_size": 0.003}), scene).H.astype(float)
    share = H[:, 0, 0].sum() / H.sum()                   # sensor 0's part of the energy
    l2_share = np.linalg.norm(H[:, 0, 0]) ** 2 / np.linalg.norm(H) ** 2
    got = analytic_agreement(_Scaled({"patch_size": 0.003}), scene)
    assert got.total == pytest.approx(2.0 + share, rel=1e-6)
    assert got.worst_sensor == pytest.approx(2.0, rel=1e-6)
    assert got.relative_l2 == pytest.approx(np.sqrt(1.0 + 3.0 * l2_share), rel=1e-6)
    assert relative_l2([2.0, 1.2], [2.0, 0.0]) == pytest.approx(0.6, rel=1e-15)

"""A glossy reflectance lobe: the simulators' physics (cos^k of the half vector's angle),
``rsd_prior``'s operator with it, and the exponent fitted jointly from simulated captures
(``lobe.fit``)."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.common.errors import ConfigError, FitError
from nlosfw.evaluation.splits import split_field
from nlosfw.image.plane_convolution import grid_layout
from nlosfw.model.physics.operator import (
    OperatorOptions,
    SceneOperator,
    VoxelLattice,
    direct_fields,
)
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.physics import three_bounce
from nlosfw.simulate.scene import GeometryItem, scene_from_config
from nlosfw.testing import fixtures, heldout_error_db, tiny_scene_config
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import PhasorField
from tests.model.physics.test_prior import _geometry

#: One voxel plane at the patch's depth, voxels a quarter of the kept points' spacing apart.
OPTIONS = {"depth": {"range": [0.5, 0.5]}, "lateral_step": 1 / 32, "l1_weight": 1e-3,
           "iterations": 300, "workers": 1}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_the_lobe_is_cos_k_of_the_half_vectors_angle():
    """Against the half vector written out with unit vectors: a tilted surface element, a
    laser spot and four sensors; for a confocal scan the lobe is cos^k at the sensor."""
    p = np.array([[0.1, -0.05, 0.6]])
    n = _unit(np.array([[0.2, -0.1, -1.0]]))
    laser = np.array([-0.2, 0.1, 0.0])
    sensors = np.array([[0.3, 0.2, 0.0], [-0.4, -0.3, 0.0], [0.0, 0.0, 0.0], [0.1, -0.5, 0.0]])
    h = _unit(_unit(laser - p) + _unit(sensors - p))
    cos_h = np.abs(h @ n[0])
    lambertian = three_bounce(laser, p, n, np.ones(1), sensors)[1]
    glossy = three_bounce(laser, p, n, np.ones(1), sensors, lobe=np.array([6.0]))[1]
    np.testing.assert_allclose(glossy / lambertian, cos_h[None] ** 6, rtol=1e-12)
    confocal = three_bounce(sensors, p, n, np.ones(1), sensors, lobe=np.array([6.0]))[1]
    flat = three_bounce(sensors, p, n, np.ones(1), sensors)[1]
    np.testing.assert_allclose(confocal / flat, np.abs(_unit(sensors - p) @ n[0])[None] ** 6,
                               rtol=1e-12)


def test_the_operator_with_a_lobe_is_the_simulators_physics_for_a_confocal_scan():
    """Voxels facing the wall: the operator's field (FFT path and direct sum) is the sum of
    three_bounce's weights with the same lobe, times pi^3, to 1e-10."""
    wall = fixtures.rect_wall_grid((5, 6), 0.06, center=(0.02, -0.01))
    lattice = VoxelLattice(np.array([0.4, 0.47]), (-0.12, -0.15), (0.06, 0.06), (4, 5))
    geometry = _geometry(confocal=True)
    freqs = np.array([3.0, 4.5])
    albedo = np.random.default_rng(0).random(lattice.volume_shape)
    options = OperatorOptions(amplitude="lambertian", lobe=5.0)
    vox = lattice.points().reshape(-1, 3)
    pts = wall.reshape(-1, 3)
    path, weight = three_bounce(pts, vox, np.tile([0.0, 0.0, -1.0], (vox.shape[0], 1)),
                                albedo.reshape(-1), pts, lobe=np.full(vox.shape[0], 5.0))
    expected = (np.pi**3 * weight[None] * np.exp(-2j * np.pi * freqs[:, None, None]
                                                 * path[None])).sum(axis=1)
    expected = expected.reshape((freqs.size,) + wall.shape[:2])
    got = SceneOperator(lattice, grid_layout(wall), geometry, freqs, options).forward(albedo)
    assert np.linalg.norm(got - expected) / np.linalg.norm(expected) < 1e-10
    direct = direct_fields(lattice, albedo, pts, geometry, freqs, options)
    assert np.linalg.norm(direct.reshape(expected.shape) - expected) < 1e-10 * np.linalg.norm(
        expected)
    lambertian = SceneOperator(lattice, grid_layout(wall), geometry, freqs).forward(albedo)
    assert np.linalg.norm(lambertian - expected) > 0.1 * np.linalg.norm(expected)


def patch_field(lobe: float = 0.0, confocal: bool = True) -> PhasorField:
    """The field of an 8 cm patch 0.5 m from a 1 m wall of 16 x 16 points with the given
    lobe, rendered by the analytic simulator (noise-free; 10 frequencies, 2-4 cycles/m)."""
    config = tiny_scene_config(confocal=confocal, resolution=16, bins=300, bin_width=0.006,
                               target=(0.03, -0.02, 0.5), patch=0.08)
    config["geometry"][0]["lobe"] = lobe
    capture = AnalyticSimulator({}).simulate(scene_from_config(config))
    return FFTTransform({"n_frequencies": 10, "f_min": 2.0, "f_max": 4.0}).transform(capture)


def _patch_fit(lobe: float, confocal: bool, options: dict) -> tuple[dict, float]:
    """rsd_prior fitted on every other point of :func:`patch_field`: (fitted values,
    held-out error in dB at the other points)."""
    field = patch_field(lobe, confocal)
    split = split_field(field, spatial_step=2, spectral="none")
    model = RSDPriorFieldModel({**OPTIONS, **options})
    report = model.fit(split.train_field)
    predicted = model.predict(field.wall_xyz[..., :2], field.frequencies)
    return report.fitted, heldout_error_db(predicted, field.values, ~split.spatial_mask)


@pytest.mark.parametrize("lobe, tolerance", [(0.0, 0.5), (4.0, 0.6), (8.0, 0.8)])
def test_fit_lobe_recovers_the_exponent_of_a_confocal_capture(lobe, tolerance):
    """Measured: 0 -> 0.0, 4 -> 3.70, 8 -> 8.12; the held-out error with the fitted lobe
    is about -26 dB for every lobe (the Lambertian model's: -15.0 dB at 4, -10.7 at 8)."""
    fitted, error = _patch_fit(lobe, True, {"lobe": {"fit": True}})
    assert fitted["lobe_exponent"] == pytest.approx(lobe, abs=tolerance)
    assert error < -24.0
    if lobe:
        _, lambertian = _patch_fit(lobe, True, {})
        assert error < lambertian - 10.0


def test_a_single_spot_lobe_is_fitted_as_an_effective_exponent():
    """For a single laser spot the operator's lobe is the product of its legs' half-powers,
    not the half vector's: a k = 8 lobe with the spot in front of the patch is fitted as
    about 3.5, the held-out error still falling by 10 dB (-15.5 to -25.3 dB)."""
    fitted, error = _patch_fit(8.0, False, {"lobe": {"fit": True}})
    _, lambertian = _patch_fit(8.0, False, {})
    assert 2.0 < fitted["lobe_exponent"] < 6.0
    assert error < lambertian - 8.0


def test_a_fitted_lobe_is_saved_and_predicts_the_same(tmp_path):
    wall = fixtures.rect_wall_grid((8, 8), 1 / 8)
    config = tiny_scene_config(confocal=True, resolution=8, bins=300, bin_width=0.006,
                               target=(0.03, -0.02, 0.5), patch=0.08)
    config["geometry"][0]["lobe"] = 6.0
    capture = AnalyticSimulator({}).simulate(scene_from_config(config))
    field = FFTTransform({"n_frequencies": 6, "f_min": 2.0, "f_max": 4.0}).transform(capture)
    model = RSDPriorFieldModel({**OPTIONS, "iterations": 60, "lobe": {"fit": True}})
    model.fit(field)
    model.save(tmp_path / "m.npz")
    loaded = RSDPriorFieldModel.load(tmp_path / "m.npz")
    xy = wall[..., :2] + 0.01
    np.testing.assert_array_equal(loaded.predict(xy, field.frequencies),
                                  model.predict(xy, field.frequencies))


@pytest.mark.parametrize("options, option", [
    ({"lobe": {"exponent": -1.0}}, "lobe.exponent"),
    ({"lobe": {"exponent": 4.0}, "amplitude": "point"}, "lobe"),
    ({"lobe": {"fit": True}, "amplitude": "inverse_square"}, "lobe"),
    ({"lobe": {"fit": True, "exponent": 4.0}}, "lobe.exponent"),
    ({"lobe": {"fit": True, "max": 0.0}}, "lobe.max"),
    ({"lobe": {"tolerance": 0.0}}, "lobe.tolerance"),
])
def test_lobe_options_are_checked(options, option):
    with pytest.raises(ConfigError) as err:
        RSDPriorFieldModel(options)
    assert err.value.option == option


def test_a_lobe_on_a_point_or_below_zero_is_refused_and_a_flat_simulator_refuses_lobes():
    with pytest.raises(ConfigError, match="no normal") as err:
        GeometryItem(type="point", lobe=2.0)
    assert err.value.option == "lobe"
    with pytest.raises(ConfigError, match="must be >= 0"):
        GeometryItem(lobe=-0.5)

    class Flat(AnalyticSimulator):
        renders_lobes = False

    config = tiny_scene_config()
    config["geometry"][0]["lobe"] = 3.0
    scene = scene_from_config(config)
    with pytest.raises(ConfigError, match="Lambertian surfaces only") as err:
        Flat({}).simulate(scene)
    assert err.value.option == "scene.geometry[0].lobe"
    AnalyticSimulator({}).check(scene)                      # renders them


def test_fit_lobe_needs_points_to_hold_out():
    config = tiny_scene_config(confocal=True, resolution=3, bins=300, bin_width=0.006,
                               target=(0.03, -0.02, 0.5), patch=0.08)
    capture = AnalyticSimulator({}).simulate(scene_from_config(config))
    field = FFTTransform({"n_frequencies": 4, "f_min": 2.0, "f_max": 4.0}).transform(capture)
    model = RSDPriorFieldModel({**OPTIONS, "iterations": 10, "lobe": {"fit": True}})
    with pytest.raises(FitError, match="at least 10 of them, got 9"):
        model.fit(field)

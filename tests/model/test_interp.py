"""The ``interp`` baseline: exactness on cubics, convergence order, extrapolation, files."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.interp import InterpFieldModel, spline_weights
from nlosfw.testing import fixtures
from nlosfw.transform.field import PhasorField

GEOM = CaptureGeometry(kind=CaptureKind.SINGLE_SPOT, laser_point=np.zeros(3))


def _cubic(x, y, f):
    """A complex polynomial of degree 3 in each of x, y and f (reproduced exactly)."""
    return ((1 + 0.5j) * x**3 - 0.7 * x * y**2 + (0.2 - 1j) * y**3 + 0.3j * f**3 * x
            + 0.8 * f**2 - (0.1 + 0.4j) * f * y + 2.0)


def _field_of(fn, n: int = 8, freqs=np.linspace(1.0, 3.0, 6)) -> PhasorField:
    wall = fixtures.wall_grid(n)
    x, y = wall[..., 0][None], wall[..., 1][None]
    f = np.asarray(freqs, float)[:, None, None]
    return PhasorField(values=fn(x, y, f), frequencies=np.asarray(freqs, float),
                       wall_xyz=wall, geometry=GEOM)


def test_reproduces_training_samples_exactly():
    field = fixtures.smooth_field(n=10)
    model = InterpFieldModel()
    model.fit(field)
    pred = model.predict(field.wall_xyz[..., :2], field.frequencies)
    np.testing.assert_allclose(pred, field.values, rtol=0, atol=1e-12)


@pytest.mark.parametrize("extrapolation", ["cubic", "nearest"])
def test_tricubic_polynomials_are_exact_inside_the_hull(extrapolation):
    field = _field_of(_cubic)
    model = InterpFieldModel({"extrapolation": extrapolation, "demodulate": False})
    model.fit(field)
    rng = np.random.default_rng(0)
    lo, hi = field.wall_xyz[0, 0, 0], field.wall_xyz[0, -1, 0]
    pts = rng.uniform(lo, hi, (50, 2))
    freqs = rng.uniform(1.0, 3.0, 7)
    expected = _cubic(pts[None, :, 0], pts[None, :, 1], freqs[:, None])
    np.testing.assert_allclose(model.predict(pts, freqs), expected, rtol=1e-10, atol=1e-10)


def test_cubic_extrapolation_continues_the_polynomial():
    field = _field_of(_cubic)
    model = InterpFieldModel({"extrapolation": "cubic", "demodulate": False})
    model.fit(field)
    pts = np.array([[0.6, -0.55], [-0.7, 0.52]])     # outside the hull (+-0.4375)
    freqs = np.array([0.8, 3.3])
    expected = _cubic(pts[None, :, 0], pts[None, :, 1], freqs[:, None])
    np.testing.assert_allclose(model.predict(pts, freqs), expected, rtol=1e-9, atol=1e-9)


def test_nearest_extrapolation_clamps_to_the_hull():
    field = _field_of(_cubic)
    model = InterpFieldModel({"extrapolation": "nearest", "demodulate": False})
    model.fit(field)
    edge = field.wall_xyz[0, -1, 0]
    out = model.predict(np.array([[edge + 0.3, 0.1]]), np.array([5.0]))
    at_edge = model.predict(np.array([[edge, 0.1]]), np.array([3.0]))
    np.testing.assert_allclose(out, at_edge, rtol=1e-12)
    assert out[0, 0] == pytest.approx(_cubic(edge, 0.1, 3.0), rel=1e-10)


def test_error_converges_at_fourth_order_on_a_point_scatterer():
    # cubic splines converge as h^4 for smooth fields: halving the spacing must cut the
    # mid-cell error by about 16 (at least 8 allowing for boundary effects)
    target = (0.1, -0.05, 0.8)
    dense = fixtures.point_phasor_field(target, n=64, frequencies=(3.0,))
    errors = []
    for n in (16, 32):
        coarse = fixtures.point_phasor_field(target, n=n, frequencies=(3.0,))
        model = InterpFieldModel()
        model.fit(coarse)
        inner = np.abs(dense.wall_xyz[..., 0]) < 0.4
        inner &= np.abs(dense.wall_xyz[..., 1]) < 0.4
        pred = model.predict(dense.wall_xyz[..., :2], dense.frequencies)
        err = np.abs(pred[0][inner] - dense.values[0][inner])
        errors.append(np.linalg.norm(err) / np.linalg.norm(dense.values[0][inner]))
    assert errors[0] < 0.05
    assert errors[0] / errors[1] > 8


def test_unsorted_axes_give_the_same_result():
    field = fixtures.smooth_field(n=8)
    flipped = field.replace(values=field.values[::-1, :, ::-1],
                            frequencies=field.frequencies[::-1],
                            wall_xyz=field.wall_xyz[:, ::-1])
    pts = np.random.default_rng(1).uniform(-0.4, 0.4, (20, 2))
    a, b = InterpFieldModel(), InterpFieldModel()
    a.fit(field)
    b.fit(flipped)
    np.testing.assert_allclose(a.predict(pts, [2.5, 3.3]), b.predict(pts, [2.5, 3.3]),
                               rtol=1e-12, atol=1e-12)


def test_degenerate_axes():
    field = fixtures.smooth_field(n=8).select([3])           # one frequency: constant in f
    model = InterpFieldModel()
    model.fit(field)
    pts = field.wall_xyz[..., :2]
    np.testing.assert_allclose(model.predict(pts, [9.0])[0], field.values[0], atol=1e-12)
    w = spline_weights(np.array([0.0, 1.0]), np.array([0.25, 2.0]), "cubic")
    np.testing.assert_allclose(w, [[0.75, 0.25], [-1.0, 2.0]])


def test_rejects_non_grid_and_bad_input(tmp_path):
    field = fixtures.smooth_field(n=6)
    wall = field.wall_xyz.copy()
    wall[2, 3, 0] += 0.01
    # a wall that is not a rectilinear grid is interpolated as scattered samples, which
    # cannot continue cubic end pieces
    with pytest.raises(FitError, match="rectilinear"):
        InterpFieldModel({"extrapolation": "cubic"}).fit(field.replace(wall_xyz=wall))
    InterpFieldModel().fit(field.replace(wall_xyz=wall))
    wall[2, 3] = wall[2, 4]
    with pytest.raises(DataError, match="same wall point"):
        InterpFieldModel().fit(field.replace(wall_xyz=wall))
    with pytest.raises(FitError, match="before"):
        InterpFieldModel().predict(np.zeros((2, 2)), [1.0])
    with pytest.raises(FitError, match="zero"):
        InterpFieldModel().fit(field.replace(values=np.zeros_like(field.values)))


def test_save_load_and_parameter_count(tmp_path):
    field = fixtures.smooth_field(n=8)
    model = InterpFieldModel({"extrapolation": "cubic"})
    model.fit(field)
    assert model.n_parameters == 2 * field.values.size
    path = tmp_path / "interp.model"
    model.save(path)
    loaded = InterpFieldModel.load(path)
    assert loaded.config.extrapolation == "cubic"
    pts = np.random.default_rng(2).uniform(-0.6, 0.6, (5, 3, 2))
    np.testing.assert_array_equal(loaded.predict(pts, [2.2, 4.5]), model.predict(pts, [2.2, 4.5]))
    path.write_bytes(b"not a model")
    with pytest.raises(DataError, match="corrupt"):
        InterpFieldModel.load(path)


def test_demodulation_interpolates_a_delayed_pulse_between_sparse_frequencies():
    # one point scatterer, frequencies so sparse that the phase turns ~2.4 rad per step:
    # a spline through P fails, a spline through the demodulated P is nearly exact
    target = (0.05, 0.0, 0.9)
    coarse = fixtures.point_phasor_field(target, n=8, frequencies=np.linspace(4.0, 8.0, 21))
    fine_f = np.linspace(4.1, 7.9, 17)
    dense = fixtures.point_phasor_field(target, n=8, frequencies=fine_f)
    errors = {}
    for demodulate in (False, True):
        model = InterpFieldModel({"demodulate": demodulate})
        model.fit(coarse)
        pred = model.predict(dense.wall_xyz[..., :2], fine_f)
        errors[demodulate] = np.linalg.norm(pred - dense.values) / np.linalg.norm(dense.values)
    assert errors[False] > 0.1
    assert errors[True] < 0.01


def _scattered(fn, n_points: int = 60, freqs=np.linspace(1.0, 3.0, 6), seed: int = 0):
    """``fn`` sampled at random wall points, as a scattered (1, N) field."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-0.5, 0.5, (n_points, 2))
    wall = np.concatenate([xy, np.zeros((n_points, 1))], axis=1)[None]
    f = np.asarray(freqs, float)[:, None, None]
    values = fn(wall[..., 0][None], wall[..., 1][None], f)
    return PhasorField(values=values, frequencies=np.asarray(freqs, float), wall_xyz=wall,
                       geometry=GEOM)


def _linear_xy(x, y, f):
    """Linear in x and y (Clough-Tocher reproduces it exactly), cubic in f (the spline does)."""
    return ((1 + 0.5j) * x - (0.3 - 0.2j) * y + 0.4) * (1 + 0.2j * f**3 - 0.5 * f)


def test_scattered_samples_reproduce_linear_fields_and_the_samples():
    field = _scattered(_linear_xy)
    model = InterpFieldModel({"demodulate": False})
    model.fit(field)
    np.testing.assert_allclose(model.predict(field.wall_xyz[..., :2], field.frequencies),
                               field.values, rtol=0, atol=1e-12)
    inside = np.random.default_rng(1).uniform(-0.2, 0.2, (40, 2))   # inside the hull
    freqs = np.array([1.3, 2.0, 2.9])
    expected = _linear_xy(inside[None, :, 0], inside[None, :, 1], freqs[:, None])
    # exact up to the tolerance (1e-6) of scipy's iterative estimate of the gradients
    np.testing.assert_allclose(model.predict(inside, freqs), expected, rtol=1e-7, atol=1e-8)


def test_scattered_samples_take_the_nearest_value_outside_their_hull():
    field = _scattered(_linear_xy, n_points=30)
    model = InterpFieldModel({"demodulate": False})
    model.fit(field)
    points = field.wall_xyz[0, :, :2]
    query = np.array([[2.0, 2.0], [-3.0, 0.1]])
    nearest = [np.argmin(np.linalg.norm(points - q, axis=1)) for q in query]
    pred = model.predict(query, field.frequencies)
    np.testing.assert_allclose(pred, field.values[:, 0, nearest], rtol=0, atol=1e-12)
    # two samples have no triangulation: every query takes the nearest
    two = field.replace(values=field.values[:, :, :2], wall_xyz=field.wall_xyz[:, :2])
    model.fit(two)
    pred = model.predict(np.array([[-1.0, -1.0], [1.0, 1.0]]), two.frequencies)
    near = [np.argmin(np.linalg.norm(two.wall_xyz[0, :, :2] - q, axis=1))
            for q in ([-1.0, -1.0], [1.0, 1.0])]
    np.testing.assert_allclose(pred, two.values[:, 0, near], rtol=0, atol=1e-12)


def test_scattered_interpolation_converges_on_a_smooth_field():
    """A smooth field (two low spatial frequencies): the error at held-out grid points falls
    by more than 4x when the scattered samples go from 100 to 400."""
    def smooth(x, y, f):
        return np.exp(1j * (2.0 * x + 1.5 * y) * f) + 0.5 * np.cos(3 * y) * f

    dense = _field_of(smooth, n=24)
    query = dense.wall_xyz[4:-4, 4:-4, :2]
    errors = []
    for n_points in (100, 400):
        model = InterpFieldModel({"demodulate": False})
        model.fit(_scattered(smooth, n_points=n_points, seed=2))
        pred = model.predict(query, dense.frequencies)
        truth = dense.values[:, 4:-4, 4:-4]
        errors.append(np.linalg.norm(pred - truth) / np.linalg.norm(truth))
    assert errors[1] < errors[0] / 4 and errors[1] < 0.01


def test_scattered_save_and_load(tmp_path):
    field = _scattered(_linear_xy)
    model = InterpFieldModel()
    model.fit(field)
    assert model.n_parameters == 2 * field.values.size
    path = tmp_path / "scattered.model"
    model.save(path)
    loaded = InterpFieldModel.load(path)
    pts = np.random.default_rng(3).uniform(-0.7, 0.7, (4, 5, 2))
    np.testing.assert_array_equal(loaded.predict(pts, [1.5, 2.5]), model.predict(pts, [1.5, 2.5]))

"""``rsd_prior``'s additive background (``background: constant``): a point scatterer's
closed-form field plus known complex offsets per frequency, the offsets recovered by the
joint fit; none in the data, none fitted; the projection against its definition."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.common.errors import ConfigError
from nlosfw.evaluation.splits import split_field
from nlosfw.model.physics.background import BackgroundProjection, WallBackground
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.testing import fixtures
from nlosfw.transform.field import PhasorField
from tests.model.physics.test_prior import _geometry, _point_field

WALL = fixtures.rect_wall_grid((16, 16), 1 / 16)
FREQS = np.linspace(2.0, 4.0, 10)
TARGET = (WALL[0, 0, 0] + 9 / 16, WALL[0, 0, 1] + 5 / 16, 0.5)   # on the voxel lattice
OPTIONS = {"amplitude": "point", "lateral_step": 1 / 16,
           "depth": {"range": [0.45, 0.55], "step": 0.025}, "l1_weight": 1e-3, "iterations": 800,
           "precision": "double", "workers": 1}


def _scene(confocal: bool, legs: bool) -> tuple[PhasorField, np.ndarray]:
    """The point's field (device legs in its phase when ``legs``) and its RMS."""
    geometry = _geometry(confocal, legs)
    values = _point_field(TARGET, WALL, FREQS, confocal)
    if legs:
        values = values * np.exp(-2j * np.pi * FREQS[:, None, None]
                                 * geometry.device_path(WALL)[None])
    field = PhasorField(values=values, frequencies=FREQS, wall_xyz=WALL, geometry=geometry)
    return field, values


def _offsets(rms: float) -> np.ndarray:
    """A smooth complex offset per frequency (a late tail: delayed, falling with f), 0.3 of
    the field's RMS at the band's start."""
    return 0.3 * rms * np.exp(-2j * np.pi * FREQS * 0.3) * 2.0 / FREQS


def _fit(field: PhasorField, background: str
         ) -> tuple[RSDPriorFieldModel, np.ndarray, dict[str, float]]:
    """Fitted on every second sample (split_field also holds one frequency out): the model,
    its prediction at every sample and frequency, what its fit report says it fitted."""
    model = RSDPriorFieldModel({**OPTIONS, "background": background})
    report = model.fit(split_field(field, spatial_step=2).train_field)
    assert (report.fitted == {}) == (background == "none")
    return model, model.predict(WALL[..., :2], FREQS), report.fitted


@pytest.mark.parametrize(("confocal", "legs"), [(False, False), (True, True)],
                         ids=["single_spot", "confocal_with_device_legs"])
def test_known_offsets_are_recovered_and_improve_held_out_error(confocal, legs):
    """The offsets are found to 1% of their RMS at every training frequency (each raw
    offset, constant over the wall, whatever the device legs do to the field's phase), and
    the unsampled wall points are predicted over ten times better than without them
    (measured: offsets to 0.24% and 0.06%, errors 0.5% against 20% and 21%; the held-out
    frequency's offset is interpolated)."""
    clean, values = _scene(confocal, legs)
    rms = float(np.sqrt(np.mean(np.abs(values) ** 2)))
    b = _offsets(rms)
    field = PhasorField(values=values + b[:, None, None], frequencies=FREQS, wall_xyz=WALL,
                        geometry=clean.geometry)
    split = split_field(field, spatial_step=2)
    unseen = ~split.spatial_mask
    kept = np.isin(FREQS, split.train_field.frequencies)
    with_bg, pred, report = _fit(field, "constant")
    fitted = with_bg.background
    assert fitted is not None
    np.testing.assert_allclose(fitted.frequencies, FREQS[kept])
    b_rms = float(np.sqrt(np.mean(np.abs(b) ** 2)))
    worst = float(np.max(np.abs(fitted.values - b[kept]))) / b_rms
    assert worst < 0.01, f"offsets off by {worst:.4f} of their RMS"
    truth = field.values[:, unseen]
    err = np.linalg.norm(pred[:, unseen] - truth) / np.linalg.norm(truth)
    _, pred_none, _ = _fit(field, "none")
    err_none = np.linalg.norm(pred_none[:, unseen] - truth) / np.linalg.norm(truth)
    print(f"offsets off by {worst:.2e}; held-out error {err:.4f}, without {err_none:.4f}")
    assert err < 0.02 and err < err_none / 10, f"error {err:.4f}, without background {err_none:.4f}"
    # the fit report: the offsets' RMS over the kept samples' RMS (the field with them)
    kept_rms = float(np.sqrt(np.mean(np.abs(split.train_field.values) ** 2)))
    assert report["background_rms_ratio"] == pytest.approx(
        np.sqrt(np.mean(np.abs(b[kept]) ** 2)) / kept_rms, rel=0.01)
    assert report["background_max_ratio"] == pytest.approx(np.abs(b[kept]).max() / kept_rms,
                                                            rel=0.01)


def test_no_offset_in_the_data_fits_none():
    """Without an offset the fitted one is under 0.1% of the field's RMS and the
    prediction is the background-free model's to 0.5% (measured 0.05% and 0.04%)."""
    field, values = _scene(False, False)
    with_bg, pred, _ = _fit(field, "constant")
    _, pred_none, _ = _fit(field, "none")
    assert with_bg.background is not None
    rms = float(np.sqrt(np.mean(np.abs(values) ** 2)))
    largest = float(np.max(np.abs(with_bg.background.values))) / rms
    change = float(np.linalg.norm(pred - pred_none) / np.linalg.norm(pred_none))
    print(f"largest offset {largest:.2e} of the RMS; prediction changed by {change:.2e}")
    assert largest < 1e-3 and change < 5e-3


def test_projection_removes_the_least_squares_offset():
    """Q p = p - v b with b = argmin ||p - v b||^2 (numpy's least squares), Q Q = Q, and
    Q is self-adjoint; v_f = exp(2 pi i f legs) with device legs, 1 without."""
    rng = np.random.default_rng(7)
    f = np.array([2.0, 2.5, 3.5])
    p = rng.normal(size=(3, 4, 5)) + 1j * rng.normal(size=(3, 4, 5))
    q = rng.normal(size=(3, 4, 5)) + 1j * rng.normal(size=(3, 4, 5))
    legs = rng.uniform(1.0, 2.0, (4, 5))
    for wall_legs in (None, legs):
        projection = BackgroundProjection(wall_legs, (4, 5))
        project = projection.projector(f)
        offsets = projection.offsets(f, p)
        for i in range(f.size):
            v = np.ones(20) if wall_legs is None else np.exp(2j * np.pi * f[i] * legs.ravel())
            b = np.linalg.lstsq(v[:, None], p[i].ravel(), rcond=None)[0][0]
            assert offsets[i] == pytest.approx(b, rel=1e-12)
            np.testing.assert_allclose(project(p)[i].ravel(), p[i].ravel() - v * b, atol=1e-12)
        np.testing.assert_allclose(project(project(p)), project(p), atol=1e-12)
        assert np.vdot(q, project(p)) == pytest.approx(np.vdot(project(q), p), rel=1e-12)


def test_offsets_between_frequencies_and_save_load(tmp_path):
    # a delayed offset (phase -2 pi f d, magnitude linear in f) is interpolated exactly
    known = np.linspace(2.0, 4.0, 5)
    d, f = 0.4, np.array([1.5, 2.2, 2.9, 3.71, 4.5])

    def delayed(x):
        return (1.0 + 0.5 * x) * np.exp(-2j * np.pi * np.clip(x, 2.0, 4.0) * d)

    bg = WallBackground(known, delayed(known))
    expected = delayed(f)
    expected[0], expected[-1] = delayed(2.0), delayed(4.0)           # the end values beyond
    np.testing.assert_allclose(bg.at(f), expected, rtol=1e-12)
    field, values = _scene(False, False)
    offset = 0.2 * np.sqrt(np.mean(np.abs(values) ** 2))
    field = PhasorField(values=values + offset, frequencies=FREQS, wall_xyz=WALL,
                        geometry=field.geometry)
    model = RSDPriorFieldModel({**OPTIONS, "iterations": 30, "background": "constant"})
    model.fit(field)
    model.save(tmp_path / "m.npz")
    loaded = RSDPriorFieldModel.load(tmp_path / "m.npz")
    pts = fixtures.wall_grid(5)[..., :2]
    f = np.array([2.1, 3.3, 5.0])
    np.testing.assert_array_equal(loaded.predict(pts, f), model.predict(pts, f))


def test_bad_background_option_is_one_line_naming_it():
    with pytest.raises(ConfigError) as caught:
        RSDPriorFieldModel({"background": "linear"})
    message = str(caught.value)
    assert message.startswith("background:") and "'none', 'constant'" in message
    assert "\n" not in message

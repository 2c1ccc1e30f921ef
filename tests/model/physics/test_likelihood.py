"""``rsd_prior``'s Poisson likelihood (``likelihood: poisson``): each wall point weighted by
the inverse variance of its samples, which the field carries (``PhasorField.variance``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.capture.photon_counts import count_scale
from nlosfw.cli import main
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.evaluation.splits import scattered_field, split_field
from nlosfw.model.physics.likelihood import sample_weights
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.model.physics.wall import wall_samples
from nlosfw.testing import fixtures, heldout_error_db
from nlosfw.testing.fixtures import tiny_capture
from nlosfw.transform.common import histogram_2d, to_field_layout
from nlosfw.transform.field import PhasorField
from tests.model.physics.test_lobe import OPTIONS, patch_field
from tests.model.physics.test_prior import _geometry


def _field_of(values: np.ndarray, variance: np.ndarray | None = None) -> PhasorField:
    wall = fixtures.rect_wall_grid(values.shape[1:], 0.1)
    return PhasorField(values, np.linspace(2.0, 3.0, values.shape[0]), wall,
                       _geometry(confocal=True), variance=variance)


def test_a_field_carries_its_variance_through_selection_and_scattering():
    rng = np.random.default_rng(0)
    values = rng.normal(size=(3, 4, 5)) + 0j
    variance = rng.random((3, 4, 5))
    field = _field_of(values, variance)
    sub = field.select([0, 2], slice(None, None, 2), slice(1, None, 2))
    np.testing.assert_array_equal(sub.variance, variance[[0, 2]][:, ::2, 1::2])
    mask = rng.random((4, 5)) < 0.5
    scattered = scattered_field(field, mask)
    np.testing.assert_array_equal(scattered.variance, variance[:, mask][:, None, :])
    assert _field_of(values).select([1]).variance is None
    for bad in (variance[:2], -variance, variance * np.nan):
        with pytest.raises(DataError, match="variance"):
            _field_of(values, bad)


def test_weights_are_the_inverse_variance_per_point_with_mean_one():
    variance = np.ones((2, 4, 4))
    variance[:, 0, 0] = 4.0              # four times noisier: half the sqrt-weight
    variance[:, 3, 3] = 0.0              # no counts: floored at 1 % of the median
    variance[1, 1, 1] = 3.0              # the mean over frequencies counts: 2
    field = _field_of(np.ones((2, 4, 4), complex), variance)
    w = sample_weights(field, wall_samples(field)) ** 2
    assert w.mean() == pytest.approx(1.0)
    assert w[0, 0] / w[0, 1] == pytest.approx(0.25)
    assert w[1, 1] / w[0, 1] == pytest.approx(0.5)
    assert w[3, 3] / w[0, 1] == pytest.approx(100.0)
    mask = np.zeros((4, 4), bool)
    mask[::2, :] = True
    mask[1, 1] = mask[3, 0] = True      # the scattered points span the 4 x 4 grid
    scattered = scattered_field(field, mask)
    ws = sample_weights(scattered, wall_samples(scattered)) ** 2
    assert np.all(ws[~mask] == 0) and ws[mask].mean() == pytest.approx(1.0)
    assert ws[1, 1] / ws[0, 1] == pytest.approx(0.5)


def test_poisson_without_a_variance_is_refused_in_one_line():
    field = patch_field()
    model = RSDPriorFieldModel({**OPTIONS, "likelihood": "poisson"})
    with pytest.raises(ConfigError, match="model.likelihood") as err:
        model.fit(field)
    assert "\n" not in str(err.value) and "least_squares" in str(err.value)


def _heldout_db(model: RSDPriorFieldModel, clean: PhasorField, kept: np.ndarray) -> float:
    """The error at the wall points not kept against the noise-free field, in dB."""
    predicted = model.predict(clean.wall_xyz[..., :2], clean.frequencies)
    return heldout_error_db(predicted, clean.values, ~kept)


def test_weighting_by_the_noise_variance_beats_least_squares_on_uneven_noise():
    """Every other point kept; a random quarter of the wall is 10 times noisier (in
    amplitude) than the rest, the noise complex Gaussian of the variance the field carries.
    Measured, noise-free error at the held-out points: least squares -13.5 dB, the
    weighted fit -22.6 dB (another noise seed: -11.9 and -23.0); with the noise the same
    everywhere the two fits are the same."""
    clean = patch_field()
    rng = np.random.default_rng(3)
    rms = float(np.sqrt(np.mean(np.abs(clean.values) ** 2)))
    sigma = np.where(rng.random(clean.grid_shape) < 0.25, 10.0, 1.0) * 0.3 * rms
    noise = (rng.normal(size=clean.values.shape) + 1j * rng.normal(size=clean.values.shape))
    noisy = clean.replace(values=clean.values + sigma * noise / np.sqrt(2),
                          variance=np.broadcast_to(sigma**2, clean.values.shape))
    split = split_field(noisy, spatial_step=2, spectral="none")
    errors = {}
    for likelihood in ("least_squares", "poisson"):
        model = RSDPriorFieldModel({**OPTIONS, "likelihood": likelihood})
        fitted = model.fit(split.train_field).fitted
        errors[likelihood] = _heldout_db(model, clean, split.spatial_mask)
    kept = sigma[split.spatial_mask] ** -2.0
    assert fitted["poisson_weight_max"] / fitted["poisson_weight_min"] == pytest.approx(100.0)
    assert fitted["poisson_weight_max"] == pytest.approx(kept.max() / kept.mean())
    assert errors["poisson"] < errors["least_squares"] - 6.0
    assert errors["poisson"] < -20.0
    # uniform variance: the weights are all one (to rounding) and the fit is least squares
    even = split.train_field.replace(variance=np.full(split.train_field.values.shape, 7.0))
    plain = RSDPriorFieldModel({**OPTIONS, "iterations": 40})
    weighted = RSDPriorFieldModel({**OPTIONS, "iterations": 40, "likelihood": "poisson"})
    assert weighted.fit(even).final_loss == pytest.approx(plain.fit(even).final_loss, rel=1e-6)
    np.testing.assert_allclose(weighted.albedo, plain.albedo, rtol=1e-4,
                               atol=1e-5 * float(plain.albedo.max()))


# ---------------------------------------------------------------- in a run
def test_a_float_capture_file_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "radiance.hdf5"
    write_capture(path, tiny_capture(resolution=8))          # analytic: float radiance
    status = main([f"capture.path={path}", "model=rsd_prior", "model.likelihood=poisson"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert err.startswith("error: model.likelihood: ") and str(path) in err
    assert "the Poisson likelihood needs raw counts" in err
    assert not (tmp_path / "outputs").exists()


@pytest.mark.parametrize("count_splitting", [[], ["split.count_splitting=true"]])
def test_a_run_gives_the_model_its_fields_poisson_variance(tmp_path, monkeypatch,
                                                          count_splitting):
    """The training field's variance is the bin width squared times each kept point's
    photon count (the capture's counts, over the count scale squared), at every frequency;
    with count splitting, half A's counts (the transform probed once, on half B)."""
    seen: list[PhasorField] = []
    fit = RSDPriorFieldModel.fit

    def recording(self, field, *args, **kwargs):
        seen.append(field)
        return fit(self, field, *args, **kwargs)

    monkeypatch.setattr(RSDPriorFieldModel, "fit", recording)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    run = tmp_path / "run"
    assert main(["scene=tiny", "scene.noise.model=poisson", "scene.noise.photons=2e5",
                 "model=rsd_prior", "model.likelihood=poisson", "model.iterations=20",
                 "split.spatial_step=2", "transform.n_frequencies=21",
                 "reconstruction.n_depths=4", "figures.enabled=false", *count_splitting,
                 f"hydra.run.dir={run}"]) == 0
    capture = read_capture(run / "capture.hdf5")
    per_point = to_field_layout(histogram_2d(capture).sum(axis=0)[None], capture)[0]
    expected = capture.delta_t**2 * per_point / count_scale(capture)
    (field,) = seen
    assert field.variance is not None and field.variance.shape == field.values.shape
    np.testing.assert_allclose(field.variance, np.broadcast_to(
        expected[::2, ::2], field.values.shape), rtol=1e-5)
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "completed" and metrics["field"]["model"]["fit"]["steps"] == 20


def test_the_kits_heldout_error_counts_only_the_held_points():
    truth = np.ones((2, 3, 4), complex)
    held = np.zeros((3, 4), bool)
    held[1, :] = True
    predicted = truth.copy()
    predicted[:, held] *= 1.1                 # 10 % off where held: -20 dB
    predicted[:, ~held] = 0.0                 # anything where not held
    assert heldout_error_db(predicted, truth, held) == pytest.approx(-20.0)

"""rsd_residual_torch (and rsd_residual_jax when nlosfw-jax is installed): rsd_prior's
field plus a penalised residual network, checked against rsd_prior fitted on its own."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

pytest.importorskip("torch")

from nlosfw.common import ConfigError
from nlosfw.evaluation import SpatialSampling, split_field
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures, heldout_error_db

HAS_JAX = bool(importlib.util.find_spec("jax") and importlib.util.find_spec("optax")
               and importlib.util.find_spec("equinox"))
BACKENDS = ["torch", pytest.param("jax", marks=pytest.mark.skipif(
    not HAS_JAX, reason="needs jax, optax and equinox (pip install nlosfw-jax)"))]

N = 12                                   # 12 x 12 wall points, 1/12 m apart
FREQUENCIES = np.linspace(2.0, 4.0, 8)
#: rsd_prior's options (a point scatterer in 0.3-0.7 m) and a small, short network.
PRIOR = {"iterations": 60, "amplitude": "point", "l1_weight": 0.001, "workers": 1,
         "depth": {"range": [0.3, 0.7]}}
NETWORK = {"network_steps": 200, "network_lr": 2e-3, "network_batch_size": 0,
           "network_validation_fraction": 0.0, "network_hidden": [16, 16], "device": "cpu"}


def _scene(offset: float):
    """(full field, kept samples, held-out mask): a point scatterer's exact field plus a
    smooth complex offset over the wall that is the same at every frequency (a zero-delay
    term, which no scene in the depth range 0.3-0.7 m produces), ``offset`` times the
    scatterer's RMS; every other sample in x and y is kept."""
    field = fixtures.point_field((0.1, -0.05, 0.5), (N, N), 1 / N, FREQUENCIES)
    x, y = field.wall_xyz[..., 0], field.wall_xyz[..., 1]
    rms = float(np.sqrt(np.mean(np.abs(field.values) ** 2)))
    term = offset * rms * (1 + 0.8 * x - 0.6 * y) * np.exp(0.5j)
    full = field.replace(values=(field.values + term[None]).astype(field.values.dtype))
    held = np.ones((N, N), bool)
    held[::2, ::2] = False
    return full, full.select(slice(None), slice(0, None, 2), slice(0, None, 2)), held


@pytest.fixture(scope="module")
def scene():
    full, train, held = _scene(0.5)
    prior = load_plugins().registry.create("model", "rsd_prior", PRIOR)
    prior.fit(train)
    return full, train, held, prior.predict(full.wall_xyz[..., :2], FREQUENCIES)


def _residual_model(backend: str, **options):
    return load_plugins().registry.create("model", f"rsd_residual_{backend}",
                                          {"prior": PRIOR, **NETWORK, **options})


def _heldout_nmse_db(full, held, predicted) -> float:
    return heldout_error_db(predicted, full.values, held)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_huge_penalty_gives_rsd_prior_fitted_alone(backend, scene):
    """Residual weight 1e12: the residual is the network's fit scaled by 1/(1 + 1e12), so
    the prediction is rsd_prior's (fitted on its own, same options) to ~1e-12 relative."""
    full, train, _, physics = scene
    model = _residual_model(backend, residual_weight=1e12)
    model.fit(train)
    predicted = model.predict(full.wall_xyz[..., :2], FREQUENCIES)
    assert predicted.shape == physics.shape
    scale = float(np.max(np.abs(physics)))
    assert np.max(np.abs(predicted - physics)) <= 1e-9 * scale
    # and the network did fit something: without the penalty the prediction moves
    free = _residual_model(backend, residual_weight=0.0)
    free.fit(train)
    moved = np.max(np.abs(free.predict(full.wall_xyz[..., :2], FREQUENCIES) - physics))
    assert moved > 0.05 * scale


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_residual_learns_a_smooth_term_the_physics_cannot_represent(backend, scene):
    """A zero-delay smooth offset (half the scatterer's RMS) on a point scatterer's field:
    rsd_prior, whose voxels lie 0.3-0.7 m from the wall, cannot produce it; the residual
    network does, so the held-out error (the 75% of wall points not kept, every frequency)
    falls by at least 6 dB (measured: rsd_prior -7.0 dB, torch residual -19 dB)."""
    full, train, held, physics = scene
    prior_db = _heldout_nmse_db(full, held, physics)
    model = _residual_model(backend, residual_weight=0.1)
    model.fit(train)
    residual_db = _heldout_nmse_db(full, held, model.predict(full.wall_xyz[..., :2],
                                                             FREQUENCIES))
    assert residual_db <= prior_db - 6.0, (prior_db, residual_db)
    # without the offset rsd_prior fits the scatterer closely: the test's lead is the term
    clean, clean_train, _ = _scene(0.0)
    prior = load_plugins().registry.create("model", "rsd_prior", PRIOR)
    prior.fit(clean_train)
    assert _heldout_nmse_db(clean, held, prior.predict(clean.wall_xyz[..., :2],
                                                       FREQUENCIES)) < prior_db - 6.0


def test_the_penalty_scales_the_residual_by_one_over_one_plus_the_weight(scene):
    """Same seed, weights 0 and 3: the second's departure from rsd_prior is a quarter of
    the first's at every point (the penalised minimiser, see nlosfw.model.hybrid.residual)."""
    full, train, _, physics = scene
    departures = []
    for weight in (0.0, 3.0):
        model = _residual_model("torch", residual_weight=weight)
        model.fit(train)
        departures.append(model.predict(full.wall_xyz[..., :2], FREQUENCIES) - physics)
    np.testing.assert_allclose(departures[1], departures[0] / 4,
                               atol=1e-6 * float(np.max(np.abs(departures[0]))))


def test_bad_options_are_one_line_errors_naming_the_option(scene):
    _, train, _, _ = scene
    model = _residual_model("torch", network="no_such_network")
    with pytest.raises(ConfigError, match=r"model\.network.*no_such_network.*valid: .*siren"):
        model.fit(train)
    for option, value in (("residual_weight", -1.0), ("network_steps", 0),
                          ("network_hidden", [])):
        with pytest.raises(ConfigError, match=option):
            _residual_model("torch", **{option: value})


def test_any_registered_network_can_be_the_residual(scene):
    """network=fourier: the fourier_torch network fits the residual (its prediction moves
    off rsd_prior's); the model counts the albedo's voxels plus that network's parameters.
    (4418 parameters for 576 training values over-fit: no held-out lead is asserted.)"""
    full, train, _, physics = scene
    counts = {}
    for network in ("siren", "fourier"):
        model = _residual_model("torch", network=network, residual_weight=0.1,
                                network_steps=20 if network == "fourier" else 200)
        model.fit(train)
        counts[network] = model.n_parameters
        predicted = model.predict(full.wall_xyz[..., :2], FREQUENCIES)
        assert np.all(np.isfinite(predicted))
        assert np.max(np.abs(predicted - physics)) > 1e-3 * np.max(np.abs(physics)), network
    fourier = load_plugins().registry.create("model", "fourier_torch", {
        "hidden": [16, 16], "steps": 2, "device": "cpu", "validation_fraction": 0.0})
    fourier.fit(train)
    siren = load_plugins().registry.create("model", "siren_torch", {
        "hidden": [16, 16], "steps": 2, "device": "cpu", "validation_fraction": 0.0})
    siren.fit(train)
    assert counts["fourier"] - counts["siren"] == fourier.n_parameters - siren.n_parameters
    assert counts["fourier"] != counts["siren"]


def test_held_out_wall_points_choose_the_networks_training_length(scene):
    """network_validation_fraction 0.25: a quarter of the kept wall points (with every
    frequency) validate the network; the fit reports its best validation loss and keeps
    the held-out lead over rsd_prior (at least 3 dB)."""
    full, train, held, physics = scene
    model = _residual_model("torch", residual_weight=0.1, network_validation_fraction=0.25,
                            network_patience=2)
    report = model.fit(train)
    assert report.best_val_loss is not None and np.isfinite(report.best_val_loss)
    predicted = model.predict(full.wall_xyz[..., :2], FREQUENCIES)
    assert _heldout_nmse_db(full, held, predicted) <= _heldout_nmse_db(full, held, physics) - 3


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_random_scan_fits_both_stages(backend):
    """A random quarter of the wall (36 scattered points) instead of every other point: the
    physics stage fits on the grid the points came from, the residual network on the
    scattered points, and the term is still learnt (held-out error measured: rsd_prior
    -6.4 dB, torch and JAX residual -15.0 dB)."""
    full, _, _ = _scene(0.5)
    split = split_field(full, SpatialSampling(pattern="random", step=2, seed=3),
                        spectral="none")
    held = ~split.spatial_mask
    prior = load_plugins().registry.create("model", "rsd_prior", PRIOR)
    prior.fit(split.train_field)
    pts = full.wall_xyz[..., :2]
    prior_db = _heldout_nmse_db(full, held, prior.predict(pts, FREQUENCIES))
    model = _residual_model(backend, residual_weight=0.1, network_hidden=[8, 8])
    model.fit(split.train_field)
    residual_db = _heldout_nmse_db(full, held, model.predict(pts, FREQUENCIES))
    assert residual_db <= prior_db - 6.0, (prior_db, residual_db)

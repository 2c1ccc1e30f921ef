"""PyTorch field models: forward pass against numpy, training behaviour, files, backends."""

from __future__ import annotations

import importlib.util
import time

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nlosfw_torch.models import PETorch, SirenTorch, TanhTorch  # noqa: E402

from nlosfw.common import ConfigError, DataError, FitError  # noqa: E402
from nlosfw.evaluation import field_metrics, split_field  # noqa: E402
from nlosfw.model import TrainingStep, preset_config  # noqa: E402
from nlosfw.testing import (  # noqa: E402
    BACKEND_CASES,
    assert_backend_matches_numpy,
    fixtures,
)

HAS_JAX = importlib.util.find_spec("jax") is not None and importlib.util.find_spec("optax")
FAST = {"steps": 150, "eval_every": 25, "batch_size": 256, "device": "cpu"}
MODELS = {"tanh": TanhTorch, "pe": PETorch, "siren": SirenTorch}


def _point_field(n: int = 24, n_f: int = 12):
    return fixtures.point_phasor_field((0.1, -0.05, 0.7), n=n,
                                       frequencies=np.linspace(2.0, 3.0, n_f))


@pytest.mark.parametrize(("family", "mode"), BACKEND_CASES)
def test_forward_matches_numpy_reference(family, mode):
    assert_backend_matches_numpy(MODELS[family], mode)


def test_fit_learns_and_reports_progress():
    field = _point_field()
    steps: list[TrainingStep] = []
    model = SirenTorch({**FAST, "steps": 300, "eval_every": 50})
    report = model.fit(field, on_step=steps.append)
    assert [s.step for s in steps] == [50, 100, 150, 200, 250, 300]
    assert all(s.total_steps == 300 and s.val_loss is not None for s in steps)
    assert steps[-1].loss < 0.2 * steps[0].loss
    assert report.steps == 300 and len(report.history) == 6
    pred = model.predict(field.wall_xyz[..., :2], field.frequencies)
    err = np.linalg.norm(pred - field.values) / np.linalg.norm(field.values)
    assert err < 0.1


def test_same_seed_same_model_other_seed_other_model():
    field = _point_field(12, 6)
    pts = fixtures.wall_grid(7)[..., :2]
    a = SirenTorch({**FAST, "seed": 3})
    b = SirenTorch({**FAST, "seed": 3})
    c = SirenTorch({**FAST, "seed": 4})
    for m in (a, b, c):
        m.fit(field)
    np.testing.assert_array_equal(a.predict(pts, [2.5]), b.predict(pts, [2.5]))
    assert not np.array_equal(a.predict(pts, [2.5]), c.predict(pts, [2.5]))


def test_divergence_is_a_one_line_fit_error():
    model = TanhTorch({**FAST, "lr": 1e4, "lr_schedule": "constant"})
    with pytest.raises(FitError, match="diverged") as err:
        model.fit(_point_field(12, 6))
    assert "\n" not in str(err.value)
    with pytest.raises(FitError, match="before"):          # no half-trained model is left
        model.predict(np.zeros((2, 2)), [2.0])


def test_early_stopping_and_time_budget(monkeypatch):
    field = _point_field(12, 6)
    # a validation field the training data contradicts: validation loss only rises
    contrary = field.replace(values=-field.values)
    model = SirenTorch({**FAST, "steps": 2000, "eval_every": 10, "patience": 3})
    report = model.fit(field, validation=contrary)
    assert report.stopped_early and report.steps < 2000
    # the budget against a clock that reads 0.25 s later at each look (the start, then
    # once a step), not the machine's: the loop stops at the first step past 0.3 s
    clock = iter(np.arange(10**4) * 0.25)
    monkeypatch.setattr(time, "perf_counter", lambda: float(next(clock)))
    model = SirenTorch({**FAST, "steps": 10**6, "max_seconds": 0.3})
    report = model.fit(field)
    monkeypatch.undo()
    assert report.steps == 2 and not report.stopped_early


def test_single_mode_blends_neighbouring_networks():
    field = _point_field(12, 5)
    model = TanhTorch({**FAST, "mode": "single", "hidden": (20, 20, 20)})
    model.fit(field)
    assert model.n_networks == 5
    assert model.n_parameters == 5 * 942
    pts = fixtures.wall_grid(5)[..., :2]
    f0, f1 = field.frequencies[1], field.frequencies[2]
    p0, p1 = model.predict(pts, [f0]), model.predict(pts, [f1])
    mid = model.predict(pts, [0.25 * f0 + 0.75 * f1])
    tau = model._norm.delay
    fm = 0.25 * f0 + 0.75 * f1
    expected = (0.25 * p0 * np.exp(2j * np.pi * (f0 - fm) * tau)
                + 0.75 * p1 * np.exp(2j * np.pi * (f1 - fm) * tau))
    np.testing.assert_allclose(mid, expected, rtol=1e-4, atol=1e-6 * np.abs(p0).max())
    # below the band: the lowest network, its demodulated field carried to the new frequency
    fb, first = 0.5 * field.frequencies[0], field.frequencies[0]
    below = model.predict(pts, [fb])
    expected = model.predict(pts, [first]) * np.exp(2j * np.pi * (first - fb) * tau)
    np.testing.assert_allclose(below, expected, rtol=1e-4, atol=1e-6 * np.abs(p0).max())


def test_presets_before_and_after_fit():
    assert SirenTorch(preset_config("thesis_siren")).n_parameters == 3362
    assert PETorch(preset_config("thesis_pe_multi")).n_parameters == 3938
    with pytest.raises(FitError, match="after fit"):
        _ = TanhTorch(preset_config("thesis_tanh_single")).n_parameters
    model = TanhTorch(preset_config("thesis_tanh_single", steps=2))
    model.fit(_point_field(8, 1))
    assert model.n_parameters == 942
    assert sum(w.size for w in model.weights()) == 942


def test_bad_device_is_a_config_error():
    with pytest.raises(ConfigError, match="device"):
        SirenTorch({**FAST, "device": "nonsense"}).fit(_point_field(8, 2))


def test_loading_another_family_fails(tmp_path):
    model = SirenTorch(FAST)
    model.fit(_point_field(8, 3))
    model.save(tmp_path / "siren.npz")
    with pytest.raises(DataError, match="'siren_torch' field model, not 'tanh_torch'"):
        TanhTorch.load(tmp_path / "siren.npz")


# ------------------------------------------------------------------ torch against JAX
needs_jax = pytest.mark.skipif(not HAS_JAX, reason="needs jax and optax (pip install nlosfw-jax)")


@needs_jax
@pytest.mark.parametrize("family", ["siren", "tanh"])
def test_files_load_across_backends(tmp_path, family):
    from nlosfw_jax import models as jm

    jax_cls = {"siren": jm.SirenJax, "tanh": jm.TanhJax}[family]
    model = MODELS[family](FAST)
    model.fit(_point_field(12, 4))
    path = tmp_path / "m.npz"
    model.save(path)
    with pytest.raises(DataError, match="not"):
        jax_cls.load(path)
    other = jax_cls.load(path, allow_other_backend=True)
    pts = fixtures.wall_grid(9)[..., :2]
    freqs = np.array([2.2, 2.9])
    np.testing.assert_allclose(other.predict(pts, freqs), model.predict(pts, freqs),
                               rtol=1e-4, atol=1e-5 * np.abs(model.predict(pts, freqs)).max())


@needs_jax
@pytest.mark.slow
@pytest.mark.parametrize("family", ["tanh", "pe", "siren"])
def test_torch_and_jax_reach_held_out_errors_within_20_percent(family):
    from nlosfw_jax import models as jm

    jax_cls = {"tanh": jm.TanhJax, "pe": jm.PEJax, "siren": jm.SirenJax}[family]
    full = _point_field(24, 12)
    split = split_field(full, spatial_step=2, spectral="interleaved", spectral_fraction=0.2)
    options = {**FAST, "steps": 400, "batch_size": 512}
    errors = {}
    for name, cls in (("torch", MODELS[family]), ("jax", jax_cls)):
        model = cls(options)
        model.fit(split.train_field)
        pred = model.predict(full.wall_xyz[..., :2], full.frequencies)
        m = field_metrics(full, pred, split)
        errors[name] = (m["heldout_pixels"]["relative_l2"],
                        m["heldout_frequencies"]["relative_l2"])
    for t, j in zip(errors["torch"], errors["jax"], strict=True):
        assert t < 0.5 and j < 0.5, errors
        assert abs(t - j) <= 0.2 * max(t, j), errors

"""JAX field models: forward pass against numpy, training behaviour, files.

The torch-against-JAX agreement tests live in the torch plugin's suite.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")

from nlosfw_jax.models import PEJax, SirenJax, TanhJax

from nlosfw.common import ConfigError, DataError, FitError
from nlosfw.model import preset_config
from nlosfw.testing import BACKEND_CASES, assert_backend_matches_numpy, fixtures

FAST = {"steps": 150, "eval_every": 25, "batch_size": 256, "device": "cpu"}


def _point_field(n: int = 24, n_f: int = 12):
    return fixtures.point_phasor_field((0.1, -0.05, 0.7), n=n,
                                       frequencies=np.linspace(2.0, 3.0, n_f))


@pytest.mark.parametrize(("family", "mode"), BACKEND_CASES)
def test_forward_matches_numpy_reference(family, mode):
    assert_backend_matches_numpy({"tanh": TanhJax, "pe": PEJax, "siren": SirenJax}[family], mode)


def test_fit_learns_and_is_deterministic():
    field = _point_field()
    pts = fixtures.wall_grid(7)[..., :2]
    a = SirenJax({**FAST, "steps": 300})
    report = a.fit(field)
    assert report.history[-1]["loss"] < 0.2 * report.history[0]["loss"]
    pred = a.predict(field.wall_xyz[..., :2], field.frequencies)
    assert np.linalg.norm(pred - field.values) / np.linalg.norm(field.values) < 0.1
    b = SirenJax({**FAST, "steps": 300})
    b.fit(field)
    np.testing.assert_array_equal(a.predict(pts, [2.5]), b.predict(pts, [2.5]))


def test_divergence_is_a_one_line_fit_error():
    with pytest.raises(FitError, match="diverged") as err:
        TanhJax({**FAST, "lr": 1e4, "lr_schedule": "constant"}).fit(_point_field(12, 6))
    assert "\n" not in str(err.value)


def test_single_mode_and_presets():
    model = TanhJax(preset_config("thesis_tanh_single", steps=20))
    model.fit(_point_field(8, 3))
    assert model.n_networks == 3 and model.n_parameters == 3 * 942
    assert SirenJax(preset_config("thesis_siren")).n_parameters == 3362


def test_bad_device_and_foreign_file(tmp_path):
    with pytest.raises(ConfigError, match="device"):
        SirenJax({**FAST, "device": "tpu:7"}).fit(_point_field(8, 2))
    model = PEJax(FAST)
    model.fit(_point_field(8, 3))
    model.save(tmp_path / "pe.npz")
    with pytest.raises(DataError, match="'pe_jax' field model, not 'siren_jax'"):
        SirenJax.load(tmp_path / "pe.npz")
    again = PEJax.load(tmp_path / "pe.npz")
    pts = fixtures.wall_grid(5)[..., :2]
    np.testing.assert_array_equal(again.predict(pts, [2.4]), model.predict(pts, [2.4]))

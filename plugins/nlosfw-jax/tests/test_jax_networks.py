"""Any equinox module as a field: fixed arrays, complex outputs, single mode, files."""

from __future__ import annotations

import types

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")
eqx = pytest.importorskip("equinox")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from nlosfw_jax.backend import Fixed  # noqa: E402

from nlosfw.common import FitError  # noqa: E402
from nlosfw.model import NeuralFieldConfig  # noqa: E402
from nlosfw.plugins import hookimpl, load_plugins  # noqa: E402
from nlosfw.testing import fixtures  # noqa: E402

FAST = {"steps": 60, "eval_every": 20, "batch_size": 0, "device": "cpu"}


class ComplexNet(eqx.Module):
    """A fixed random projection, then a trained linear map to a complex value."""

    proj: Fixed
    weight: jax.Array
    bias: jax.Array

    def __init__(self, config, shape, key):
        k1, k2 = jax.random.split(key)
        self.proj = Fixed(jax.random.normal(k1, (shape.in_dim, 8)))
        self.weight = 0.1 * jax.random.normal(k2, (16, 2))
        self.bias = jnp.zeros(2)

    def __call__(self, x):
        angle = x @ self.proj.value
        out = jnp.concatenate([jnp.cos(angle), jnp.sin(angle)], axis=1) @ self.weight + self.bias
        return out[:, 0] + 1j * out[:, 1]


def not_a_module(config, shape, key):
    return lambda x: x


def _registry(**networks):
    @hookimpl
    def register_networks(register):
        for name, factory in networks.items():
            register(name, backend="jax", factory=factory, config=NeuralFieldConfig)

    module = types.ModuleType("in_process_jax_networks")
    module.register_networks = register_networks
    return load_plugins(env={}, extra=[("my-dist", "mine", module)]).registry


def _field():
    return fixtures.smooth_field(n=8, frequencies=np.linspace(2.0, 3.0, 5), seed=4)


def test_fixed_arrays_are_saved_not_trained_and_outputs_may_be_complex(tmp_path):
    registry = _registry(cplx=ComplexNet)
    spec = registry.get("model", "cplx_jax")
    assert dict(spec.requires)["equinox"] == "equinox"
    short, long = (registry.create("model", "cplx_jax", {**FAST, "steps": s}) for s in (1, 60))
    for m in (short, long):
        m.fit(_field())
    assert long.n_parameters == 16 * 2 + 2               # the projection is not a parameter
    short.save(tmp_path / "a.npz")
    long.save(tmp_path / "b.npz")
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        np.testing.assert_array_equal(a["a_proj"], b["a_proj"])
        assert not np.allclose(a["a_weight"], b["a_weight"])
    again = type(long).load(tmp_path / "b.npz")
    pts = fixtures.wall_grid(5)[..., :2]
    np.testing.assert_array_equal(again.predict(pts, [2.4]), long.predict(pts, [2.4]))
    assert np.all(np.isfinite(long.predict(pts, [2.4])))


def test_single_mode_gives_every_copy_its_own_start(tmp_path):
    model = _registry(cplx=ComplexNet).create("model", "cplx_jax",
                                              {**FAST, "mode": "single", "steps": 2})
    model.fit(_field())
    assert model.n_networks == 5 and model.n_parameters == 5 * 34
    model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as data:
        proj = data["a_proj"]
    assert proj.shape == (5, 2, 8) and not np.allclose(proj[0], proj[1])


def test_a_factory_must_return_an_equinox_module():
    model = _registry(bad=not_a_module).create("model", "bad_jax", FAST)
    with pytest.raises(FitError, match="not an equinox.Module"):
        model.fit(_field())

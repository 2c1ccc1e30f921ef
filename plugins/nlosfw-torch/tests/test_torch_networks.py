"""Any torch module as a field: registration, outputs, fixed arrays, old files."""

from __future__ import annotations

import json
import types

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nlosfw_torch.models import PETorch, SirenTorch  # noqa: E402

from nlosfw.common import DataError, FitError, PluginError  # noqa: E402
from nlosfw.model import NeuralFieldConfig, preset_config  # noqa: E402
from nlosfw.model.neural import (  # noqa: E402
    FieldNormalisation,
    forward_numpy,
    init_parameters,
    network_inputs,
    resolve_architecture,
)
from nlosfw.plugins import NetworkBackend, hookimpl, load_plugins  # noqa: E402
from nlosfw.testing import fixtures  # noqa: E402

FAST = {"steps": 60, "eval_every": 20, "batch_size": 0, "device": "cpu"}


class PairNet(torch.nn.Module):
    """A small MLP returning (N, 2) (or, with ``complex_out``, the same values as complex)."""

    def __init__(self, config: NeuralFieldConfig, shape, complex_out: bool = False) -> None:
        super().__init__()
        self.net = torch.nn.Sequential(torch.nn.Linear(shape.in_dim, 16), torch.nn.Tanh(),
                                       torch.nn.Linear(16, 2))
        self.register_buffer("scale", torch.full((2,), 0.5))
        self.complex_out = complex_out

    def forward(self, x):
        out = self.net(x) * self.scale
        return torch.complex(out[:, 0], out[:, 1]) if self.complex_out else out


def complex_net(config, shape):
    return PairNet(config, shape, complex_out=True)


def wrong_net(config, shape):
    return torch.nn.Linear(shape.in_dim, 3)


def _registry(**networks):
    """A registry with in-process networks registered through the hook."""
    @hookimpl
    def register_networks(register):
        for name, factory in networks.items():
            register(name, backend="torch", factory=factory, config=NeuralFieldConfig,
                     test_config=FAST)

    module = types.ModuleType("in_process_networks")
    module.register_networks = register_networks
    return load_plugins(env={}, extra=[("my-dist", "mine", module)]).registry


def _field():
    return fixtures.smooth_field(n=8, frequencies=np.linspace(2.0, 3.0, 5), seed=4)


def test_a_registered_network_is_a_field_model_named_after_its_backend():
    registry = _registry(pairs=PairNet)
    spec = registry.get("model", "pairs_torch")
    assert spec.distribution == "my-dist" and spec.entry_point == "mine"
    assert dict(spec.requires)["torch"] == "torch==2.13.0"
    model = spec.create({"steps": 5})
    assert type(model).model_name() == "pairs_torch" and model.family == "pairs"
    # 3 -> 16 -> 2 with biases; the buffer `scale` is not a parameter
    assert model.n_parameters == 3 * 16 + 16 + 16 * 2 + 2


def test_complex_output_trains_like_pairs(tmp_path):
    registry = _registry(pairs=PairNet, cplx=complex_net)
    pts = fixtures.wall_grid(6)[..., :2]
    preds = {}
    for name in ("pairs_torch", "cplx_torch"):
        model = registry.create("model", name, FAST)
        model.fit(_field())
        preds[name] = model.predict(pts, [2.3, 2.9])
    # same seed: the same initial weights; complex (N,) is read as (Re, Im)
    np.testing.assert_allclose(preds["cplx_torch"], preds["pairs_torch"], rtol=1e-5,
                               atol=1e-6 * np.abs(preds["pairs_torch"]).max())


def test_single_mode_trains_one_copy_per_frequency_from_distinct_starts(tmp_path):
    model = _registry(pairs=PairNet).create("model", "pairs_torch",
                                            {**FAST, "mode": "single", "steps": 1})
    model.fit(_field())
    assert model.n_networks == 5 and model.n_parameters == 5 * (2 * 16 + 16 + 16 * 2 + 2)
    model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as data:
        w = data["a_net.0.weight"]
        scale = data["a_scale"]
    assert w.shape == (5, 16, 2) and scale.shape == (5, 2)     # (x, y) in single mode
    assert not np.allclose(w[0], w[1])              # each copy its own initialisation
    np.testing.assert_array_equal(scale, 0.5)       # buffers are not trained


def test_a_wrong_output_shape_is_a_one_line_fit_error():
    model = _registry(wrong=wrong_net).create("model", "wrong_torch", FAST)
    with pytest.raises(FitError, match=r"must return \(N, 2\)") as err:
        model.fit(_field())
    assert "\n" not in str(err.value)


def test_registration_names_a_valid_backend():
    @hookimpl
    def register_networks(register):
        register("bad", backend="tensorflow", factory="x:y", config=NeuralFieldConfig)

    module = types.ModuleType("bad_networks")
    module.register_networks = register_networks
    with pytest.raises(PluginError, match="backend 'tensorflow'; valid: torch, jax"):
        load_plugins(env={}, extra=[("bad-dist", "bad", module)])
    assert [e.value for e in NetworkBackend] == ["torch", "jax"]


def test_the_old_engine_keyword_still_registers_with_a_warning():
    @hookimpl
    def register_networks(register):
        register("pairs", engine="torch", factory=PairNet, config=NeuralFieldConfig)

    module = types.ModuleType("old_networks")
    module.register_networks = register_networks
    with pytest.warns(DeprecationWarning, match=r"engine=\.\.\.\) is deprecated.*backend="):
        host = load_plugins(env={}, extra=[("old-dist", "old", module)])
    assert host.registry.get("model", "pairs_torch").factory.backend == NetworkBackend.torch


@pytest.mark.parametrize(("options", "problem"), [
    ({"backend": "torch", "factory": "x:y", "config": NeuralFieldConfig, "colour": "red"},
     "unknown option 'colour'"),
    ({"backend": "torch", "config": NeuralFieldConfig}, "no 'factory' (required: factory, "
                                                        "config)"),
    ({"factory": "x:y", "config": NeuralFieldConfig}, "no 'backend'; valid: torch, jax"),
    ({"backend": "torch", "engine": "torch", "factory": "x:y", "config": NeuralFieldConfig},
     "both backend and engine"),
])
def test_a_wrong_registration_option_is_a_one_line_error(options, problem):
    @hookimpl
    def register_networks(register):
        register("odd", **options)

    module = types.ModuleType("odd_networks")
    module.register_networks = register_networks
    with pytest.raises(PluginError) as err:
        load_plugins(env={}, extra=[("odd-dist", "odd", module)])
    assert str(err.value).startswith(f"odd-dist: network 'odd' is registered with {problem}")
    assert "\n" not in str(err.value)


def test_blocked_networks_are_not_registered():
    host = load_plugins(env={"NLOSFW_PLUGINS": "-siren_torch"})
    assert "siren_torch" not in host.registry.names("model")
    assert "pe_torch" in host.registry.names("model")


def _write_version_1_file(path, model, config, norm, arch, params):
    """A file as nlosfw wrote it before networks were pluggable (format version 1)."""
    header = {"format": "nlosfw-field-model", "version": 1, "model": model,
              "config": config, "architecture": arch.to_dict(),
              "normalisation": norm.to_dict(), "backend": "torch", "family": arch.family}
    arrays = {f"a_p{i}": p for i, p in enumerate(params)}
    with open(path, "wb") as fh:
        np.savez(fh, header=np.array(json.dumps(header)), **arrays)


@pytest.mark.parametrize("preset", ["thesis_siren", "thesis_pe_multi"])
def test_version_1_files_still_load(tmp_path, preset):
    field = _field()
    norm = FieldNormalisation.fit(field, 0.9, demodulate=True)
    config = preset_config(preset)
    family = "siren" if preset == "thesis_siren" else "pe"
    arch = resolve_architecture(family, config, (32, 32), 135)
    params = init_parameters(arch, 0, seed=9)
    options = {k: (list(v) if isinstance(v, tuple) else getattr(v, "value", v))
               for k, v in config.__dict__.items()}
    path = tmp_path / "old.npz"
    _write_version_1_file(path, f"{family}_torch", options, norm, arch, params)
    cls = SirenTorch if family == "siren" else PETorch
    model = cls.load(path)
    assert model.n_parameters == {"thesis_siren": 3362, "thesis_pe_multi": 3938}[preset]
    pts = fixtures.wall_grid(5)[..., :2].reshape(-1, 2)
    freqs = np.array([2.2, 2.7])
    # independent reference: the numpy network on the stored weights, de-normalised
    x = network_inputs(arch, norm.coords(pts), norm.freqs(freqs))
    expected = norm.values(forward_numpy(arch, params, x).reshape(2, -1, 2), freqs)
    np.testing.assert_allclose(model.predict(pts, freqs), expected, rtol=1e-4,
                               atol=1e-4 * np.abs(expected).max())


def test_a_file_of_another_network_shape_is_refused(tmp_path):
    model = SirenTorch({**FAST, "hidden": (8, 8)})
    model.fit(_field())
    model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as data:
        arrays = {k: data[k] for k in data.files}
    arrays["a_layers.0.weight"] = arrays["a_layers.0.weight"][:, :4]
    with open(tmp_path / "bad.npz", "wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(DataError, match="layers.0.weight has shape"):
        SirenTorch.load(tmp_path / "bad.npz")

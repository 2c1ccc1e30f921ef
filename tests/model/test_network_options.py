"""What a field model names outside its own options, checked before a run: the network of
the neural volume and of the neural residual, and the network's own options that the
neural volume passes on (``model.network_options``)."""

from __future__ import annotations

import pytest

from nlosfw.cli import main
from nlosfw.common import ConfigError
from nlosfw.model import NeuralVolumeConfig
from nlosfw.plugins import load_plugins
from nlosfw.plugins.networks import NEURAL_VOLUME_TEST_CONFIG
from nlosfw.testing.checks_model import fit_fixture


def _refused(tmp_path, monkeypatch, capsys, *overrides: str) -> str:
    """The one error line of a run refused before it starts (exit 2, no run directory)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    status = main(["scene=tiny", "figures.enabled=false", *overrides,
                   f"hydra.run.dir={tmp_path / 'run'}"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert not (tmp_path / "run").exists()
    return err


@pytest.mark.parametrize("overrides, expected", [
    (["model=neural_volume_torch", "model.network=nope"],
     "error: model.network: 'nope' is not a network registered for torch; valid: "),
    (["model=rsd_residual_torch", "model.network=nope"],
     "error: model.network: 'nope' is not a network registered for torch; valid: "),
    (["model=siren_torch", "+compare.vol.name=neural_volume_torch",
      "+compare.vol.network=nope"],
     "error: compare.vol.network: 'nope' is not a network registered for torch; "),
    (["model=neural_volume_torch", "+model.network_options.bogus=1"],
     "error: model.network_options.bogus: unknown option; valid options: "),
    (["model=neural_volume_torch", "+model.network_options.omega0_first=-1"],
     "error: model.network_options.omega0_first: must be > 0"),
    (["model=neural_volume_torch", "model.network=hashgrid",
      "+model.network_options.omega0_first=30"],
     "error: model.network_options.omega0_first: unknown option; "),
    (["model=neural_volume_torch", "+model.network_options.steps=5"],
     "error: model.network_options.steps: is set by the neural volume's own options"),
])
def test_what_a_model_names_is_checked_before_the_run(tmp_path, monkeypatch, capsys,
                                                      overrides, expected):
    pytest.importorskip("torch")
    err = _refused(tmp_path, monkeypatch, capsys, *overrides)
    assert err.startswith(expected), err


def test_the_network_gets_its_options_and_the_volumes(monkeypatch):
    """The albedo network a fit trains is built with ``network_options`` over the volume's
    widths, seed and steps."""
    pytest.importorskip("torch")
    model = load_plugins().registry.create("model", "neural_volume_torch", {
        **NEURAL_VOLUME_TEST_CONFIG, "network_options": {"omega0_first": 33.0},
        "network_hidden": [12, 10]})
    seen = []

    class Stop(Exception):
        pass

    def train(problem, on_step=None):
        seen.append(problem.network_config)
        raise Stop

    monkeypatch.setattr(model, "train", train)
    with pytest.raises(Stop):
        model.fit(fit_fixture(physical=True))
    (config,) = seen
    assert config.omega0_first == 33.0 and list(config.hidden) == [12, 10]
    assert config.steps == model.config.steps and config.seed == model.config.seed
    default = NeuralVolumeConfig(network="siren")
    assert default.network_options == {}
    with pytest.raises(ConfigError, match="network_options.lr"):
        NeuralVolumeConfig(network="siren", network_options={"lr": 0.1})


def test_the_jax_volume_checks_its_network_options_too(tmp_path, monkeypatch, capsys):
    pytest.importorskip("jax")
    err = _refused(tmp_path, monkeypatch, capsys, "model=neural_volume_jax",
                   "+model.network_options.omega0_first=0")
    assert err.startswith("error: model.network_options.omega0_first: must be > 0"), err

"""What the split of nlosfw.model into families changed for users and plugins, and how the
old spellings are met: options renamed into groups (``depth_range`` -> ``depth.range``; the
hybrids' ``rsd_prior`` options -> ``prior.*``) are refused in one line that gives the new
name, model files written before load, the defaults are the same, the old public names
still import with a DeprecationWarning, and a resumed sweep says which option is new."""

from __future__ import annotations

import dataclasses
import importlib
import json
import warnings

import numpy as np
import pytest

from nlosfw.cli import main
from nlosfw.common.config import config_from_mapping, config_to_dict
from nlosfw.common.errors import ConfigError
from nlosfw.model import (
    NeuralVolumeConfig,
    RSDPriorConfig,
    RSDPriorFieldModel,
    RSDResidualConfig,
)
from nlosfw.model.model_files import stored_config
from nlosfw.model.physics import DepthOptions, PriorOptions
from nlosfw.model.physics.config import FLAT_NAMES, GROUPED
from nlosfw.pipeline.lifecycle import EarlierRun, verdict
from nlosfw.pipeline.settings import RunSettings
from nlosfw.testing import fixtures
from tests.model.physics.test_prior import _field, _point_field

#: The defaults of rsd_prior's options before they were grouped (flat names).
FLAT_DEFAULTS = {
    "iterations": 150, "l1_weight": 0.02, "tv_weight": 0.0, "amplitude": "lambertian",
    "lobe": 0.0, "fit_lobe": False, "lobe_max": 20.0, "lobe_tolerance": 0.25,
    "fit_frequencies": 32, "depth_range": [], "depth_step": None, "lateral_step": None,
    "depth_threshold": 0.1, "depth_iterations": 40, "depth_margin": 0.05,
    "power_iterations": 20, "step": 0.9, "tolerance": 0.0, "precision": "single",
    "workers": -1, "cache_mb": 1024.0, "background": "none", "temporal_response": "none",
    "time_offset": False, "response_rounds": 5, "likelihood": "least_squares",
    "counts_iterations": 100, "counts_stop": "likelihood", "counts_bin": None}


def _at(tree: dict, dotted: str) -> object:
    for part in dotted.split("."):
        tree = tree[part]
    return tree


def _flat(config: RSDPriorConfig) -> dict[str, object]:
    """``config``'s options under the flat names they had before."""
    plain = config_to_dict(config)
    return {"seed": plain["seed"], "device": plain["device"],
            **{name: _at(plain, GROUPED.get(name, name)) for name in FLAT_NAMES}}


# ------------------------------------------------------------------ the same defaults
def test_the_grouped_options_keep_the_defaults_they_had():
    assert _flat(RSDPriorConfig()) == {"seed": 0, "device": "auto", **FLAT_DEFAULTS}
    assert RSDResidualConfig().prior_config() == RSDPriorConfig()
    # the neural volume fits every frequency by default, rsd_prior 32: its group says so
    volume = NeuralVolumeConfig(seed=3)
    assert volume.prior.fit_frequencies == 0
    assert volume.prior_config() == RSDPriorConfig(seed=3, fit_frequencies=0)
    assert config_from_mapping(NeuralVolumeConfig, {"prior": {"workers": 1}}).prior == \
        dataclasses.replace(volume.prior, workers=1)


# ------------------------------------------------------------------ old names refused
@pytest.mark.parametrize(("cls", "options", "option", "new"), [
    (RSDPriorConfig, {"depth_range": [0.4, 0.6]}, "model.depth_range", "model.depth.range"),
    (RSDPriorConfig, {"fit_lobe": True}, "model.fit_lobe", "model.lobe.fit"),
    (RSDPriorConfig, {"counts_bin": 0.01}, "model.counts_bin", "model.counts.bin"),
    (RSDPriorConfig, {"temporal_response": "gaussian"}, "model.temporal_response",
     "model.response.temporal"),
    (RSDPriorConfig, {"lobe": 2.0}, "model.lobe", "model.lobe.exponent"),
    (RSDResidualConfig, {"iterations": 5}, "model.iterations", "model.prior.iterations"),
    (RSDResidualConfig, {"depth_step": 0.1}, "model.depth_step", "model.prior.depth.step"),
    (NeuralVolumeConfig, {"lobe": 2.0}, "model.lobe", "model.prior.lobe.exponent"),
    (NeuralVolumeConfig, {"fit_frequencies": 8}, "model.fit_frequencies",
     "model.prior.fit_frequencies"),
])
def test_an_old_option_name_is_refused_naming_the_new_one(cls, options, option, new):
    with pytest.raises(ConfigError) as err:
        config_from_mapping(cls, options, "model")
    assert err.value.option == option
    assert f"write {new}" in err.value.problem and "\n" not in str(err.value)


def test_the_new_group_takes_a_mapping_and_an_unknown_name_is_still_unknown():
    config = config_from_mapping(RSDPriorConfig, {"lobe": {"exponent": 2.0}}, "model")
    assert config.lobe.exponent == 2.0
    with pytest.raises(ConfigError, match="unknown option; valid options: .*depth"):
        config_from_mapping(RSDPriorConfig, {"no_such_option": 1}, "model")


@pytest.mark.parametrize(("override", "line"), [
    ("model.depth_range=[0.4,0.6]",
     "error: model.depth_range: was renamed; write model.depth.range instead"),
    ("+model.fit_lobe=true", "error: model.fit_lobe: was renamed; write model.lobe.fit instead"),
    ("model.lobe=2", "error: model.lobe: is a group of options now; write model.lobe.exponent "
                     "(the option it was) or model.lobe.<option>"),
])
def test_the_command_line_refuses_an_old_name_in_one_line(tmp_path, monkeypatch, capsys,
                                                          override, line):
    monkeypatch.chdir(tmp_path)
    status = main(["scene=tiny", "model=rsd_prior", override,
                   f"hydra.run.dir={tmp_path / 'run'}"])
    err = capsys.readouterr().err
    assert status == 2 and err == line + "\n"
    assert not (tmp_path / "run").exists()


def test_the_neural_volume_refuses_a_prior_option_it_does_not_use():
    with pytest.raises(ConfigError) as err:
        config_from_mapping(NeuralVolumeConfig, {"prior": {"likelihood": "poisson"}}, "model")
    assert err.value.option == "model.prior.likelihood" and "least squares" in err.value.problem


# ------------------------------------------------------------------ old model files
def test_a_model_file_written_before_the_grouping_loads(tmp_path):
    """An rsd_prior file whose config holds the flat names (what nlosfw wrote before) loads,
    options and predictions as the current file's."""
    wall = fixtures.rect_wall_grid((8, 8), 1 / 8)
    freqs = np.linspace(2.0, 4.0, 6)
    field = _field(_point_field((0.1, 0.0, 0.5), wall, freqs, True), wall, freqs, True)
    model = RSDPriorFieldModel({"depth": {"range": [0.45, 0.55]}, "iterations": 20,
                                "lobe": {"tolerance": 0.5}})
    model.fit(field)
    model.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        arrays = {k: np.array(data[k]) for k in data.files}
    header = json.loads(str(arrays["header"][()]))
    header["config"] = _flat(model.config)
    assert header["config"]["depth_range"] == [0.45, 0.55]
    arrays["header"] = np.array(json.dumps(header))
    with open(tmp_path / "old.npz", "wb") as fh:
        np.savez(fh, **arrays)
    loaded = RSDPriorFieldModel.load(tmp_path / "old.npz")
    assert loaded.config == model.config
    pts = fixtures.wall_grid(5)[..., :2]
    np.testing.assert_array_equal(loaded.predict(pts, freqs), model.predict(pts, freqs))


def test_the_hybrids_stored_flat_configs_are_read_into_their_group():
    residual = RSDResidualConfig(seed=2, network_steps=30, prior=PriorOptions(
        depth=DepthOptions(range=(0.3, 0.7)), fit_frequencies=0))
    old = {**{k: v for k, v in config_to_dict(residual).items() if k != "prior"},
           **{k: v for k, v in _flat(residual.prior_config()).items()
              if k not in ("seed", "device")}}
    assert stored_config(RSDResidualConfig, {"config": old}) == residual
    volume = config_from_mapping(NeuralVolumeConfig, {"prior": {
        "lateral_step": 0.02, "lobe": {"fit": True}, "depth": {"step": 0.05}}})
    flat = _flat(volume.prior_config())
    old = {**{k: v for k, v in config_to_dict(volume).items() if k != "prior"},
           **{k: flat[k] for k in ("amplitude", "lobe", "fit_lobe", "lobe_max",
                                   "fit_frequencies", "depth_range", "depth_step",
                                   "lateral_step", "depth_threshold", "depth_iterations",
                                   "depth_margin", "precision", "workers")}}
    assert stored_config(NeuralVolumeConfig, {"config": old}) == volume


# ------------------------------------------------------------------ old import paths
def test_the_names_nlosfw_model_exported_before_still_import_with_a_warning():
    import nlosfw.model as model

    assert len(model.__all__) == 17
    for old, target in model.MOVED.items():
        module, _, name = target.partition(":")
        with pytest.warns(DeprecationWarning, match=f"nlosfw.model.{old} is deprecated.*"
                                                    f"use {module}.{name}"):
            found = getattr(model, old)
        assert found is getattr(importlib.import_module(module), name)
        assert old not in model.__all__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in model.__all__:      # the names users import warn of nothing
            getattr(model, name)


def test_the_testing_kits_engine_names_are_the_backend_names_with_a_warning():
    import nlosfw.testing as testing

    with pytest.warns(DeprecationWarning, match="use nlosfw.testing.backends.BACKEND_CASES"):
        assert testing.ENGINE_CASES is testing.BACKEND_CASES
    with pytest.warns(DeprecationWarning):
        assert testing.assert_engine_matches_numpy is testing.assert_backend_matches_numpy


def test_the_plugin_systems_engine_names_are_the_backend_names_with_a_warning():
    import nlosfw.plugins as plugins
    from nlosfw.plugins import BACKENDS, NetworkBackend, NetworkSpec

    with pytest.warns(DeprecationWarning, match="use nlosfw.plugins.networks.NetworkBackend"):
        assert plugins.NetworkEngine is NetworkBackend
    with pytest.warns(DeprecationWarning, match="use nlosfw.plugins.networks.BACKENDS"):
        assert plugins.ENGINES is BACKENDS
    spec = NetworkSpec("pairs", NetworkBackend.jax, "x:y", "x:Y")
    with pytest.warns(DeprecationWarning, match="NetworkSpec.backend"):
        assert spec.engine is NetworkBackend.jax
    assert spec.model_name == "pairs_jax"


def test_a_network_model_setting_engine_class_gets_it_as_backend_class():
    from nlosfw.model.neural import Backend, NeuralFieldModel

    class Mine(Backend):             # never instantiated here
        pass

    with pytest.warns(DeprecationWarning, match="Old.engine_class is deprecated"):
        class Old(NeuralFieldModel):
            engine_class = Mine
    assert Old.backend_class is Mine


# ------------------------------------------------------------------ resumed sweeps
def test_a_resumed_sweep_job_says_an_option_is_new_to_its_earlier_run(tmp_path):
    """A job run before the grouping (config.yaml with ``model.depth_range``) and resumed
    after (``model.depth.range``): the refusal says the new option was not in that run."""
    job = tmp_path / "0"
    job.mkdir()
    old = {"model": {"name": "rsd_prior", "depth_range": [0.4, 0.6]}}
    (job / "config.yaml").write_text(json.dumps(old))
    marker = {"format": "nlosfw-run", "version": 1, "pid": 1, "host": "x",
              "config_hash": "0", "files": ["config.yaml"]}
    new = {"model": {"name": "rsd_prior", "depth": {"range": [0.4, 0.6]}}}
    with pytest.raises(ConfigError) as err:
        verdict(job, EarlierRun(marker=marker, status="completed"), new, RunSettings(),
                resume=True)
    assert err.value.option == "model.depth.range"
    assert f"is an option the run in {job} did not have" in err.value.problem
    assert "renamed since: nlosfw's changelog" in err.value.problem
    assert "\n" not in str(err.value)


def test_a_hybrid_names_a_prior_option_in_its_group_when_the_fit_refuses_it():
    """rsd_prior's fit refuses a field it cannot place (one frequency, no time span) naming
    ``model.depth.range``; inside the neural volume that option is ``model.prior.depth.range``."""
    from nlosfw.model.hybrid import NeuralVolumeFieldModel
    from nlosfw.model.neural import NeuralFieldModel

    class Volume(NeuralVolumeFieldModel):
        backend = "numpy"

        @classmethod
        def network_class(cls, name: str) -> type[NeuralFieldModel]:
            return NeuralFieldModel            # not reached: the lattice is refused first

    one = _field(np.ones((1, 4, 4), complex), fixtures.rect_wall_grid((4, 4), 0.1),
                 np.array([2.0]), False)
    with pytest.raises(ConfigError, match="give .near, far.") as err:
        RSDPriorFieldModel().fit(one)
    assert err.value.option == "model.depth.range"
    with pytest.raises(ConfigError, match="give .near, far.") as err:
        Volume().fit(one)
    assert err.value.option == "model.prior.depth.range"

"""The plugin system: discovery, registries, filtering, lazy loading, errors."""

import enum
import json
import subprocess
import sys
import types
from dataclasses import dataclass

import pytest

from nlosfw import ConfigError, PluginError, PluginKind, Simulator, SimulatorConfig
from nlosfw.plugins import hookimpl, load_plugins
from nlosfw.plugins import manager as manager_module
from nlosfw.plugins.manager import PluginFilter


@dataclass(frozen=True)
class DummyConfig(SimulatorConfig):
    gain: float = 1.0


class DummySimulator(Simulator):
    config_class = DummyConfig

    def render(self, geometry):  # pragma: no cover - never rendered here
        raise NotImplementedError


def plugin_module(name: str, **register_kwargs) -> types.ModuleType:
    """A plugin module object registering one simulator called ``name``."""

    @hookimpl
    def register_simulators(register):
        register(name, DummySimulator, config=DummyConfig, **register_kwargs)

    module = types.ModuleType(f"plugin_{name}")
    module.register_simulators = register_simulators
    return module


def test_builtins_register_through_the_entry_point():
    host = load_plugins(env={})
    spec = host.registry.get("simulator", "analytic")
    assert spec.distribution == "nlosfw" and spec.entry_point == "builtin"
    assert {"fft", "wavelet"} <= set(host.registry.names("transform"))
    assert {"rsd", "fft"} <= set(host.registry.names("imager"))
    assert "interp" in host.registry.names("model")


def test_duplicate_names_an_error_naming_both_distributions():
    with pytest.raises(PluginError) as info:
        load_plugins(env={}, extra=[("dist-one", "one", plugin_module("twin")),
                                    ("dist-two", "two", plugin_module("twin"))])
    message = str(info.value)
    assert "duplicate simulator plugin 'twin'" in message
    assert "dist-one" in message and "dist-two" in message


def test_an_unknown_registration_option_is_a_one_line_error():
    with pytest.raises(PluginError) as info:
        load_plugins(env={}, extra=[("dist-y", "y", plugin_module("yew", colour="red"))])
    assert str(info.value) == (
        "dist-y: simulator plugin 'yew' is registered with unknown option 'colour'; valid: "
        "config, requires, description, test_config, expected_failures, capabilities")


def test_unknown_name_lists_valid_names():
    host = load_plugins(env={}, extra=[("dist-x", "x", plugin_module("zeta"))])
    with pytest.raises(PluginError) as info:
        host.registry.get("simulator", "nope")
    assert str(info.value) == "unknown simulator plugin 'nope'; valid: analytic, " + ", ".join(
        sorted(set(host.registry.names("simulator")) - {"analytic"}))
    assert "zeta" in str(info.value)


def test_environment_variable_blocks_and_allows():
    extra = [("dist-x", "x", plugin_module("zeta"))]
    blocked = load_plugins(env={"NLOSFW_PLUGINS": "-zeta,-model:interp"}, extra=extra)
    assert ("simulator", "zeta") not in blocked.registry
    assert ("model", "interp") not in blocked.registry
    assert ("simulator", "analytic") in blocked.registry
    only = load_plugins(env={"NLOSFW_PLUGINS": "zeta,imager:rsd"}, extra=extra)
    assert [s.qualified_name for s in only.registry.specs()] == ["simulator:zeta", "imager:rsd"]
    no_builtin = load_plugins(env={"NLOSFW_PLUGINS": "-builtin"}, extra=extra)
    assert not [s for s in no_builtin.registry.specs() if s.distribution == "nlosfw"]
    assert ("simulator", "zeta") in no_builtin.registry


def test_filter_parsing():
    rules = PluginFilter.parse(" a, -b ,+c,, -model:d ")
    assert rules.allow == {"a", "c"} and rules.block == {"b", "model:d"}


def test_missing_dependency_gives_the_pip_command():
    module = plugin_module("needy", requires={"surely_missing_mod_xyz": "surely-missing==1.0"})
    host = load_plugins(env={}, extra=[("dist-n", "n", module)])
    spec = host.registry.get("simulator", "needy")
    assert spec.install_command() == "pip install 'surely-missing==1.0'"
    lazy = type(spec)(**{**spec.__dict__, "factory": "surely_missing_mod_xyz.sim:Sim"})
    with pytest.raises(PluginError) as info:
        lazy.load()
    assert str(info.value) == ("simulator plugin 'needy' needs surely_missing_mod_xyz, which is "
                               "not installed; run: pip install 'surely-missing==1.0'")


def test_plugins_create_validated_configs():
    host = load_plugins(env={}, extra=[("dist-x", "x", plugin_module("zeta"))])
    sim = host.registry.create("simulator", "zeta", {"gain": 2, "seed": 3})
    assert sim.config == DummyConfig(seed=3, gain=2.0)
    with pytest.raises(Exception, match=r"simulator.gain: must be a number"):
        host.registry.create("simulator", "zeta", {"gain": "high"})


def test_broken_entry_point_is_reported_not_fatal(monkeypatch):
    class BrokenEntryPoint:
        name = "broken"
        dist = types.SimpleNamespace(metadata={"Name": "nlosfw-broken"})

        def load(self):
            raise ImportError("No module named 'nowhere'")

    real = manager_module.entry_points

    def fake_entry_points(group):
        return [*real(group=group), BrokenEntryPoint()]

    monkeypatch.setattr(manager_module, "entry_points", fake_entry_points)
    host = load_plugins(env={})
    assert "broken" in host.broken and "nlosfw-broken" in host.broken["broken"]
    assert ("simulator", "analytic") in host.registry


HEAVY = ("torch", "jax", "jaxlib", "mitsuba", "drjit", "embreex", "mitransient")


def test_import_and_listing_import_no_heavy_backend():
    code = (
        "import io, json, sys\n"
        "import nlosfw\n"
        "from rich.console import Console\n"
        "from nlosfw.app.plugins_command import plugins_command\n"
        "from nlosfw.plugins import load_plugins\n"
        "host = load_plugins()\n"
        "plugins_command(host, Console(file=io.StringIO()))\n"
        "for spec in host.registry.specs(): spec.config_class()\n"
        f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_plugins_command_lists_every_plugin():
    out = subprocess.run([sys.executable, "-m", "nlosfw", "plugins"], capture_output=True,
                         text=True, check=True, timeout=120, env={"COLUMNS": "200",
                                                                  **_env()})
    host = load_plugins()
    for spec in host.registry.specs():
        assert spec.name in out.stdout and spec.distribution in out.stdout
    assert out.stdout.count("│ ok") + out.stdout.count("missing:") >= len(host.registry)
    for kind in PluginKind:
        assert kind.value in out.stdout


def _env():
    import os

    return {k: v for k, v in os.environ.items() if k != "NLOSFW_PLUGINS"}


def test_a_third_party_config_is_checked_by_hydra_as_it_composes():
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException

    from nlosfw.app.hydra_app import (
        composition_error,
        config_dir,
        ensure_resolvers,
        register_configs,
        validate_config,
    )

    host = load_plugins(env={}, extra=[("dist-x", "x", plugin_module("zeta"))])
    register_configs(host)
    ensure_resolvers()
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = compose(config_name="config", overrides=["simulator=zeta", "simulator.gain=2"])
            assert cfg.simulator.name == "zeta" and cfg.simulator.gain == 2.0
            validate_config(cfg, host)
            with pytest.raises(HydraException) as info:
                compose(config_name="config", overrides=["simulator=zeta", "simulator.gain=x"])
    finally:
        GlobalHydra.instance().clear()
    error = composition_error(info.value)
    assert isinstance(error, ConfigError)
    assert str(error) == "simulator.gain: must be a number, got 'x' (str)"


class Renamed(str, enum.Enum):
    FAST = "fast"


@dataclass(frozen=True)
class RenamedConfig(SimulatorConfig):
    mode: Renamed = Renamed.FAST


def test_the_kit_refuses_choices_not_named_as_their_values():
    from nlosfw.plugins.registry import PluginSpec
    from nlosfw.testing.checks_common import check_config_round_trip

    spec = PluginSpec(kind=PluginKind.SIMULATOR, name="renamed", factory=DummySimulator,
                      distribution="dist-x", config=RenamedConfig)
    with pytest.raises(AssertionError, match=r"option mode: members \['FAST'\] of Renamed "
                                             r"must be named as their values"):
        check_config_round_trip(spec)

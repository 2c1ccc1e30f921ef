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
        "config, requires, description, test_config, expected_failures, capabilities, "
        "system_check")


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
        "from nlosfw.cli.plugins_command import plugins_command\n"
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

    from nlosfw.common.resources import config_dir
    from nlosfw.compose import (
        composition_error,
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


# --------------------------------------------------------------------------- plugins NAME
def _command(host, *args, width=500):
    import io

    from rich.console import Console

    from nlosfw.cli.plugins_command import plugins_command

    buffer = io.StringIO()
    status = plugins_command(host, Console(file=buffer, width=width), args)
    return status, buffer.getvalue()


def _row(text, first):
    """The whitespace-separated cells of the output line starting with ``first``."""
    for line in text.splitlines():
        if " ".join(line.split()).startswith(first + " "):
            return line.split()
    raise AssertionError(f"no line starting with {first!r} in:\n{text}")


def test_plugins_name_shows_kind_distribution_options_capabilities_plan_and_example():
    from importlib.metadata import version

    status, out = _command(load_plugins(env={}), "imager:fft")
    assert status == 0, out
    assert out.splitlines()[0] == ("imager:fft  Fast RSD: per-plane FFT convolution "
                                   "(Liu 2020)")
    assert f"distribution  nlosfw {version('nlosfw')}" in out
    assert "kind          imager (select it with imager=fft)" in out
    assert "status        ok" in out
    # the options: type, default, unit and the first sentence of the field's docstring
    assert " ".join(_row(out, "chunk_mb")) == (
        "chunk_mb float 512.0 MiB Memory budget: the field's spectrum (on frequencies or "
        "time slices) is cached when it fits in half of this; the threads' blocks of "
        "kernels stay within the other half.")
    assert " ".join(_row(out, "time")) == (
        "time float 0.0 m Virtual time (a path length) of the coherent image; 0 images the "
        "pulse as it focuses.")
    assert " ".join(_row(out, "precision"))[:33] == "precision single | double single "
    assert " ".join(_row(out, "workers")) == (
        "workers int -1 Threads (-1: all cores): depth planes are imaged in parallel, and the "
        "threads left over when there are fewer planes split each plane's FFTs.")
    # the declared capabilities, and the conformance kit's plan from them
    assert " ".join(_row(out, "progress")).startswith("progress reconstruct(..., on_progress=")
    assert "run   check_imager_reports_progress[single_spot]" in out
    assert ("skip  check_imager_point_voxels: needs capability point_voxels, which imager:fft "
            "does not declare") in out
    assert "python -m nlosfw imager=fft imager.time=0.0" in out
    assert "python -m nlosfw.testing imager:fft" in out


def test_plugins_name_of_a_network_model_reads_its_config():
    pytest.importorskip("torch")
    status, out = _command(load_plugins(env={}), "siren_torch")
    assert status == 0, out
    assert " ".join(_row(out, "max_seconds")) == (
        "max_seconds float 0.0 s Wall-clock budget of the training loop (0: none).")
    assert " ".join(_row(out, "omega0_first"))[:25] == "omega0_first float 15.0 o"
    assert "python -m nlosfw model=siren_torch model.steps=3000" in out


def test_a_name_two_kinds_use_shows_both(capsys):
    from nlosfw.cli import main

    assert main(["plugins", "lct"]) == 0
    out = capsys.readouterr().out
    assert "imager:lct" in out and "capture_format:lct" in out
    assert "kind          imager" in out and "kind          capture_format" in out


@pytest.mark.parametrize("name", ["none", "model:none"])
def test_model_none_is_explained_not_unknown(capsys, name):
    """model=none is a valid choice the README shows; `plugins none` says what it is."""
    from nlosfw.cli import main

    assert main(["plugins", name]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "model=none is not a plugin" in out and "python -m nlosfw image FILE" in out


def test_an_unknown_plugin_name_is_one_line(capsys):
    from nlosfw.cli import main

    assert main(["plugins", "nope"]) == 2
    assert capsys.readouterr().err.startswith("error: unknown plugin 'nope'; valid: "
                                              "simulator:analytic, ")
    assert main(["plugins", "sensor:fft"]) == 2
    assert capsys.readouterr().err == ("error: unknown plugin kind 'sensor' in 'sensor:fft'; "
                                       "valid: simulator, transform, model, imager, "
                                       "capture_format\n")
    assert main(["plugins", "--bogus"]) == 2
    assert capsys.readouterr().err.startswith("error: plugins: unrecognized arguments: --bogus")


def broken_plugin(factory: str, name: str = "wrecked") -> types.ModuleType:
    """A plugin module registering simulator ``name`` whose factory is the path ``factory``."""

    @hookimpl
    def register_simulators(register):
        register(name, factory, config=DummyConfig, description="a broken plugin")

    module = types.ModuleType(f"plugin_{name}")
    module.register_simulators = register_simulators
    return module


@pytest.fixture()
def failing_module(tmp_path, monkeypatch):
    """An importable module whose import fails on a missing dependency."""
    (tmp_path / "nlosfw_test_needs_dep.py").write_text(
        "import surely_missing_dependency_xyz  # noqa\n\nclass Sim:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "nlosfw_test_needs_dep"
    sys.modules.pop("nlosfw_test_needs_dep", None)


def test_the_listing_finds_a_missing_factory_module_without_importing():
    host = load_plugins(env={}, extra=[
        ("dist-w", "w", broken_plugin("nlosfw_no_such_module.sim:Simulator"))])
    status, out = _command(host)
    assert status == 0
    assert " ".join(_row(out, "│ simulator │ wrecked")) == (
        "│ simulator │ wrecked │ dist-w │ broken: module nlosfw_no_such_module.sim of "
        "nlosfw_no_such_module.sim:Simulator not found │ a broken plugin │")
    assert " ".join(_row(out, "│ simulator │ analytic")).startswith(
        "│ simulator │ analytic │ nlosfw │ ok │")
    status, out = _command(host, "--check")
    assert status == 1
    assert ("broken: simulator plugin 'wrecked' (from dist-w) cannot be imported: No module "
            "named 'nlosfw_no_such_module'") in " ".join(out.split())


def test_check_imports_every_plugin_and_shows_import_errors_and_typos(failing_module):
    host = load_plugins(env={}, extra=[
        ("dist-w", "w", broken_plugin(f"{failing_module}:Sim", "needs_dep")),
        ("dist-t", "t", broken_plugin("nlosfw.simulate.analytic:AnalyticSimulatr", "typo"))])
    # both modules exist: the quick listing cannot tell, --check and NAME import them
    _, listed = _command(host)
    listed = " ".join(listed.split())
    assert "│ needs_dep │ dist-w │ ok │" in listed and "│ typo │ dist-t │ ok │" in listed
    status, out = _command(host, "--check")
    assert status == 1
    assert " ".join(_row(out, "│ simulator │ needs_dep")) == (
        "│ simulator │ needs_dep │ dist-w │ broken: simulator plugin 'needs_dep' (from dist-w) "
        "cannot be imported: No module named 'surely_missing_dependency_xyz' │ a broken plugin │")
    assert ("broken: simulator plugin 'typo' (from dist-t) cannot be imported: AttributeError: "
            "module 'nlosfw.simulate.analytic' has no attribute 'AnalyticSimulatr'") in " ".join(
        _row(out, "│ simulator │ typo"))
    status, out = _command(host, "simulator:typo")
    assert status == 1 and "status        broken: simulator plugin 'typo'" in out
    assert "(options unavailable until the plugin imports)" in out


def test_a_run_with_a_broken_plugin_stops_with_one_line_before_any_output(
        failing_module, tmp_path, monkeypatch, capsys):
    import nlosfw.plugins
    from nlosfw.cli import main

    real = nlosfw.plugins.load_plugins
    extra = [("dist-w", "w", broken_plugin(f"{failing_module}:Sim", "needs_dep"))]
    monkeypatch.setattr(nlosfw.plugins, "load_plugins", lambda: real(extra=extra))
    monkeypatch.chdir(tmp_path)
    assert main(["simulator=needs_dep", "scene=tiny", "model=interp"]) == 2
    err = capsys.readouterr().err
    assert err == ("error: simulator plugin 'needs_dep' (from dist-w) cannot be imported: No "
                   "module named 'surely_missing_dependency_xyz' (see: python -m nlosfw plugins "
                   "simulator:needs_dep)\n")
    assert not (tmp_path / "outputs").exists()


def test_a_broken_entry_point_shows_as_broken(monkeypatch):
    class BrokenEntryPoint:
        name = "broken"
        dist = types.SimpleNamespace(metadata={"Name": "nlosfw-broken"})

        def load(self):
            raise ImportError("No module named 'nowhere'")

    real = manager_module.entry_points
    monkeypatch.setattr(manager_module, "entry_points",
                        lambda group: [*real(group=group), BrokenEntryPoint()])
    host = load_plugins(env={})
    status, out = _command(host)
    assert status == 0
    assert " ".join(_row(out, "│ ? │ broken")) == (
        "│ ? │ broken │ nlosfw-broken │ broken: entry point failed to load: ImportError: No "
        "module named 'nowhere' │ │")
    assert _command(host, "--check")[0] == 1
    status, out = _command(host, "broken")
    assert status == 1 and "entry point failed to load" in out


def test_a_capture_format_says_it_is_detected_and_forced_with_capture_format():
    status, out = _command(load_plugins(env={}), "capture_format:lct")
    assert status == 0, out
    assert ("kind          capture_format (detected from a file's content; force it with "
            "capture.format=lct)") in out
    assert "python -m nlosfw capture.path=FILE capture.format=lct" in out
    assert "capture_format=lct" not in out.replace("capture.format=lct", "")

"""Conformance checks that apply to every plugin, whatever its kind.

A check is a function ``check_*(spec)`` taking a
:class:`~nlosfw.plugins.registry.PluginSpec`; it raises ``AssertionError``
(with a message saying what was expected) when the plugin does not conform.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import typing
from collections.abc import Callable
from typing import Any

import numpy as np
import yaml

from nlosfw.common.config import config_from_mapping, config_to_dict
from nlosfw.common.errors import ConfigError, NlosfwError
from nlosfw.plugins.kinds import INTERFACES, PluginKind
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import fixtures

#: Modules that registering or listing plugins must never import.
HEAVY_MODULES = ("torch", "jax", "jaxlib", "mitsuba", "drjit", "embreex", "mitransient")


def exercise(spec: PluginSpec, options: dict[str, Any] | None = None) -> np.ndarray:
    """Run the plugin once on the tiny fixture of its kind and return its main output array."""
    options = dict(spec.test_config if options is None else options)
    plugin = spec.create(options)
    if spec.kind is PluginKind.SIMULATOR:
        return plugin.simulate(fixtures.tiny_scene()).H
    if spec.kind is PluginKind.PHASOR_TRANSFORM:
        return plugin.transform(fixtures.tiny_capture()).values
    if spec.kind is PluginKind.FIELD_MODEL:
        field = fixtures.smooth_field(n=8)
        plugin.fit(field)
        return plugin.predict(fixtures.wall_grid(12)[..., :2], field.frequencies[::3])
    if spec.kind is PluginKind.IMAGER:
        return plugin.reconstruct(fixtures.point_phasor_field(), fixtures.tiny_voxels()).intensity
    raise AssertionError(f"unknown plugin kind {spec.kind}")


def check_interface(spec: PluginSpec) -> None:
    """The factory subclasses its kind's interface and declares the registered config class."""
    factory = spec.load()
    interface = INTERFACES[spec.kind.value]
    assert isinstance(factory, type) and issubclass(factory, interface), (
        f"{spec.qualified_name}: factory {factory!r} must subclass {interface.__name__}")
    assert factory.config_class is spec.config_class(), (
        f"{spec.qualified_name}: registered config {spec.config_class().__name__} differs from "
        f"the factory's config_class {factory.config_class.__name__}")
    base = INTERFACES[spec.kind.value].config_class
    assert issubclass(spec.config_class(), base), (
        f"{spec.qualified_name}: config must derive from {base.__name__}")


def check_config_round_trip(spec: PluginSpec) -> None:
    """Defaults and test settings survive dict -> YAML -> OmegaConf (as Hydra composes it)
    -> config unchanged; the config has no field ``name`` (the selector key of its group)."""
    from omegaconf import OmegaConf

    cls = spec.config_class()
    assert dataclasses.is_dataclass(cls), f"{spec.qualified_name}: config must be a dataclass"
    assert cls.__dataclass_params__.frozen, f"{spec.qualified_name}: config must be frozen"
    assert "name" not in {f.name for f in dataclasses.fields(cls)}, (
        f"{spec.qualified_name}: a config field called 'name' would collide with the plugin "
        "name that selects it in its Hydra group")
    for options in ({}, dict(spec.test_config)):
        config = spec.make_config(options)
        plain = config_to_dict(config)
        again = yaml.safe_load(yaml.safe_dump(plain))
        assert again == json.loads(json.dumps(plain)), "config_to_dict must be YAML/JSON-safe"
        node = OmegaConf.create({"name": spec.name, **again})        # the ConfigStore node
        composed = OmegaConf.to_container(node, resolve=True)
        composed.pop("name")
        rebuilt = config_from_mapping(cls, composed, spec.kind.value)
        assert rebuilt == config, (
            f"{spec.qualified_name}: config changed in a round trip: {config} != {rebuilt}")
        instance = spec.create(options)
        assert instance.config == config, f"{spec.qualified_name}: instance lost its config"


def one_line_error(spec: PluginSpec, action: str, call: Callable[[], object],
                   expected: type[NlosfwError] = NlosfwError) -> str:
    """The text of the one-line ``expected`` error that ``call()`` must raise.

    AssertionError (naming the plugin and ``action``) when it raises nothing,
    another exception, or a message that is empty or longer than one line.
    """
    try:
        call()
    except expected as err:
        text = str(err)
        assert text and "\n" not in text, (
            f"{spec.qualified_name}: {action}: the error must be one line, got {text!r}")
        return text
    except Exception as err:  # a bare ValueError, KeyError... is not a user-facing error
        raise AssertionError(f"{spec.qualified_name}: {action}: raised {type(err).__name__} "
                             f"({err}); expected {expected.__name__}") from err
    raise AssertionError(f"{spec.qualified_name}: {action}: no error was raised")


def check_bad_config_rejected(spec: PluginSpec) -> None:
    """Unknown options and values of the wrong type give a ConfigError naming the option."""
    text = one_line_error(spec, "an unknown option",
                          lambda: spec.make_config({"no_such_option_xyz": 1}), ConfigError)
    assert "no_such_option_xyz" in text and "valid options" in text, text
    hints = typing.get_type_hints(spec.config_class())
    for f in dataclasses.fields(spec.config_class()):
        if hints[f.name] in (int, float, bool):
            try:
                spec.make_config({f.name: "not-a-number"})
            except ConfigError as err:
                assert f.name in str(err), f"error must name option {f.name}: {err}"
            else:
                raise AssertionError(f"{spec.qualified_name}: {f.name}='not-a-number' accepted")


def check_deterministic(spec: PluginSpec) -> None:
    """Two instances with the same config (and seed) produce identical output."""
    first = exercise(spec)
    second = exercise(spec)
    assert first.shape == second.shape
    assert np.all(np.isfinite(first)), f"{spec.qualified_name}: output has NaN or inf"
    np.testing.assert_array_equal(first, second, err_msg=(
        f"{spec.qualified_name}: same config and seed gave different outputs"))


def check_no_heavy_import_at_registration(spec: PluginSpec) -> None:
    """Registering the plugin and importing its config class import no heavy backend."""
    code = (
        "import json, sys\n"
        "from nlosfw.plugins import load_plugins\n"
        "host = load_plugins()\n"
        f"spec = host.registry.get({spec.kind.value!r}, {spec.name!r})\n"
        "spec.config_class(); spec.missing_requirements()\n"
        f"print(json.dumps([m for m in {HEAVY_MODULES!r} if m in sys.modules]))\n"
    )
    env = dict(os.environ)
    env.pop("NLOSFW_PLUGINS", None)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env=env, timeout=120, check=False)
    assert result.returncode == 0, f"registration failed: {result.stderr.strip()[-500:]}"
    imported = json.loads(result.stdout.strip().splitlines()[-1])
    assert not imported, (f"{spec.qualified_name}: registering it imported {imported}; import "
                          "heavy backends inside the factory module only")


COMMON_CHECKS = (
    check_interface,
    check_config_round_trip,
    check_bad_config_rejected,
    check_deterministic,
    check_no_heavy_import_at_registration,
)

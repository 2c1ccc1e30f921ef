"""Conformance checks that apply to every plugin, whatever its kind.

A check is a function ``check_*(spec, **variant_options)`` taking a
:class:`~nlosfw.plugins.registry.PluginSpec`; it raises ``AssertionError``
(with a message saying what was expected) when the plugin does not conform.
What it needs from the plugin is declared with
:func:`~nlosfw.testing.selection.requires`.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import os
import subprocess
import sys
import typing
from collections.abc import Callable, Mapping

import numpy as np
import yaml

from nlosfw.common.config import config_from_mapping, config_to_dict
from nlosfw.common.errors import ConfigError, NlosfwError
from nlosfw.common.schema import schema_class
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.kinds import INTERFACES, PluginKind
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import fixtures
from nlosfw.testing.selection import (
    FREQUENCY_MODES,
    GEOMETRIES,
    VOXEL_LAYOUTS,
    combine,
    requires,
    variant,
)

#: Modules that registering or listing plugins must never import.
HEAVY_MODULES = ("torch", "jax", "jaxlib", "mitsuba", "drjit", "embreex", "mitransient")


#: The variant :func:`exercise` runs a plugin in, per kind (the first one it declares).
EXERCISE_VARIANTS = {
    PluginKind.SIMULATOR.value: GEOMETRIES,
    PluginKind.PHASOR_TRANSFORM.value: GEOMETRIES,
    PluginKind.FIELD_MODEL.value: FREQUENCY_MODES,
    PluginKind.IMAGER.value: combine(VOXEL_LAYOUTS, GEOMETRIES),
    PluginKind.CAPTURE_FORMAT.value: (variant("", [Capability.READABLE]),),
}


def exercise(spec: PluginSpec, options: Mapping[str, object] | None = None, *,
             confocal: bool = False, single: bool = False, plane: bool = True) -> np.ndarray:
    """Run the plugin once on the tiny fixture of its kind and return its main output array.

    ``confocal``: capture geometry (simulators, transforms, imagers); ``single``: fit one
    frequency (field models); ``plane``: voxels as planes, else as a list (imagers). A
    capture format reads a file in its layout (:mod:`nlosfw.testing.checks_capture_format`).
    """
    options = dict(spec.test_config if options is None else options)
    plugin = spec.create(options)
    if spec.kind is PluginKind.CAPTURE_FORMAT:
        import tempfile
        from pathlib import Path

        from nlosfw.testing.layouts import known_captures, write_sample

        with tempfile.TemporaryDirectory() as tmp:
            path = write_sample(spec, plugin, known_captures(spec)[0], Path(tmp))
            return plugin.read(path).H
    if spec.kind is PluginKind.SIMULATOR:
        return plugin.simulate(fixtures.tiny_scene(confocal=confocal)).H
    if spec.kind is PluginKind.PHASOR_TRANSFORM:
        return plugin.transform(fixtures.tiny_capture(confocal=confocal)).values
    if spec.kind is PluginKind.FIELD_MODEL:
        field = fixtures.smooth_field(n=8)
        if single:
            field = field.select([5])
        plugin.fit(field)
        return plugin.predict(fixtures.wall_grid(12)[..., :2],
                              field.frequencies if single else field.frequencies[::3])
    if spec.kind is PluginKind.IMAGER:
        voxels = fixtures.tiny_voxels()
        field = fixtures.point_phasor_field(confocal=confocal)
        return plugin.reconstruct(field, voxels if plane else voxels.reshape(-1, 3)).intensity
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
    """Defaults and test settings survive dict -> YAML -> the plugin's Hydra group entry (as
    Hydra composes it) -> config unchanged; the config has no field ``name`` (the selector
    key of its group), and its choices are enums whose members are named as their values."""
    from omegaconf import OmegaConf

    cls = spec.config_class()
    assert dataclasses.is_dataclass(cls), f"{spec.qualified_name}: config must be a dataclass"
    try:
        setattr(spec.make_config({}), "_frozen_probe", 1)  # noqa: B010
    except dataclasses.FrozenInstanceError:
        pass
    else:
        raise AssertionError(f"{spec.qualified_name}: config must be frozen")
    assert "name" not in {f.name for f in dataclasses.fields(cls)}, (
        f"{spec.qualified_name}: a config field called 'name' would collide with the plugin "
        "name that selects it in its Hydra group")
    for f in dataclasses.fields(cls):
        choice = typing.get_type_hints(cls)[f.name]
        if isinstance(choice, type) and issubclass(choice, enum.Enum):
            renamed = [m.name for m in choice if m.name != m.value]
            assert not renamed, (
                f"{spec.qualified_name}: option {f.name}: members {renamed} of {choice.__name__} "
                "must be named as their values (OmegaConf matches enum options by name)")
    for options in ({}, dict(spec.test_config)):
        config = spec.make_config(options)
        plain = config_to_dict(config)
        again = yaml.safe_load(yaml.safe_dump(plain))
        assert again == json.loads(json.dumps(plain)), "config_to_dict must be YAML/JSON-safe"
        entry = OmegaConf.structured(schema_class(cls, spec.name))     # the ConfigStore entry
        composed = OmegaConf.to_container(OmegaConf.merge(entry, again), resolve=True)
        assert isinstance(composed, dict) and composed.pop("name") == spec.name
        rebuilt = config_from_mapping(cls, {str(k): v for k, v in composed.items()},
                                      spec.kind.value)
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


@requires(any_of=EXERCISE_VARIANTS)
def check_deterministic(spec: PluginSpec, confocal: bool = False, single: bool = False,
                        plane: bool = True) -> None:
    """Two instances with the same config (and seed) produce identical output."""
    first = exercise(spec, confocal=confocal, single=single, plane=plane)
    second = exercise(spec, confocal=confocal, single=single, plane=plane)
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

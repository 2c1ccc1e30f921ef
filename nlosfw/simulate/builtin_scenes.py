"""Built-in scenes: the ``scene`` config group shipped in ``conf/scene/<name>.yaml``.

The same YAML files (found by :func:`nlosfw.common.resources.config_dir`: the installed
``nlosfw.conf`` package, or ``conf/`` beside a checkout) serve Hydra
(``scene=thesis_two_planes``) and Python code::

    from nlosfw.simulate.builtin_scenes import builtin_scene
    scene = builtin_scene("thesis_two_planes", wall={"resolution": [32, 32]})

A scene file holds fields of :class:`nlosfw.simulate.Scene` and takes its wall, capture,
time axis and noise from the base every built-in scene shares, through Hydra's defaults
list: ``- base@_here_: default`` merges ``conf/scene/base/default.yaml`` into the scene,
then the file's own fields (``_self_``, last) override what they name.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

from nlosfw.common.errors import ConfigError
from nlosfw.common.resources import config_dir
from nlosfw.simulate.scene import Scene, scene_from_config


def builtin_scene_names() -> list[str]:
    """Names of the built-in scenes (the YAML files of the ``scene`` config group)."""
    folder = config_dir() / "scene"
    return sorted(p.name[: -len(".yaml")] for p in folder.iterdir()
                  if p.name.endswith(".yaml"))


def builtin_scene_config(name: str) -> dict[str, Any]:
    """The plain config mapping of built-in scene ``name`` (its defaults list resolved as
    Hydra composes it); unknown names list the valid ones."""
    names = builtin_scene_names()
    if name not in names:
        raise ConfigError("scene", f"unknown scene {name!r}; valid: {', '.join(names)}")
    own = _read(f"{name}.yaml")
    defaults = own.pop("defaults", [])
    if "_self_" not in defaults:
        defaults = [*defaults, "_self_"]            # Hydra's rule: own fields come last
    config: dict[str, Any] = {}
    for entry in defaults:
        if entry == "_self_":
            config = merge_config(config, own)
        elif isinstance(entry, Mapping) and len(entry) == 1:
            ((group, option),) = entry.items()
            group, _, package = str(group).partition("@")
            block = _read(f"{group}/{option}.yaml")
            config = merge_config(config, block if package == "_here_" else {group: block})
        else:
            raise ConfigError("scene", f"conf/scene/{name}.yaml: defaults entry {entry!r} is not "
                                       "'_self_', '<group>: <option>' or "
                                       "'<group>@_here_: <option>'")
    return config


def builtin_scene(name: str, **overrides: Any) -> Scene:
    """Built-in scene ``name`` with options replaced, validated like any scene config.

    Mapping overrides merge into the scene's mapping (``wall={"resolution": [8, 8]}``
    keeps the wall size); other values (``geometry=[...]``) replace it.
    """
    return scene_from_config(merge_config(builtin_scene_config(name), overrides))


def merge_config(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """A new mapping: ``base`` with ``overrides`` merged recursively into its sub-mappings."""
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge_config(out[key], value)
        else:
            out[key] = value
    return out


def _read(relative: str) -> dict[str, Any]:
    """A mapping from ``conf/scene/<relative>``."""
    path = config_dir() / "scene" / relative
    if not path.is_file():
        raise ConfigError("scene", f"conf/scene/{relative} does not exist")
    config = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not isinstance(config, dict):
        raise ConfigError("scene", f"conf/scene/{relative} does not hold a mapping")
    return config

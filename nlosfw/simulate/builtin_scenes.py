"""Built-in scenes: the ``scene`` config group shipped in ``conf/scene/<name>.yaml``.

``conf/`` is installed as the package ``nlosfw.conf``, so the same YAML files
serve Hydra (``scene=thesis_two_planes``) and Python code::

    from nlosfw.simulate.builtin_scenes import builtin_scene
    scene = builtin_scene("thesis_two_planes", wall={"resolution": [32, 32]})

Every YAML file holds exactly the fields of :class:`nlosfw.simulate.Scene`.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib.resources import files
from typing import Any

import yaml

from nlosfw.common.errors import ConfigError
from nlosfw.simulate.scene import Scene, scene_from_config

#: Package holding the ``scene`` config group.
SCENE_PACKAGE = "nlosfw.conf"


def builtin_scene_names() -> list[str]:
    """Names of the built-in scenes (the YAML files of the ``scene`` config group)."""
    folder = files(SCENE_PACKAGE) / "scene"
    return sorted(p.name[: -len(".yaml")] for p in folder.iterdir()
                  if p.name.endswith(".yaml"))


def builtin_scene_config(name: str) -> dict[str, Any]:
    """The plain config mapping of built-in scene ``name``; unknown names list the valid ones."""
    names = builtin_scene_names()
    if name not in names:
        raise ConfigError("scene", f"unknown scene {name!r}; valid: {', '.join(names)}")
    text = (files(SCENE_PACKAGE) / "scene" / f"{name}.yaml").read_text(encoding="utf-8")
    config = yaml.safe_load(text)
    if not isinstance(config, dict):
        raise ConfigError("scene", f"conf/scene/{name}.yaml does not hold a mapping")
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

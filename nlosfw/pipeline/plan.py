"""What one run will do: its validated settings and the plugins it uses, built.

:func:`make_plan` turns a resolved configuration (the plain mapping Hydra composed, or
``nlosfw.run``'s) into a :class:`RunPlan`; the :class:`~nlosfw.pipeline.Pipeline` runs a
plan and never reads the configuration again. Every mistake the configuration can hold
is a one-line error here, before the run directory is touched.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import Generic, TypeVar

from nlosfw.capture.source import FormatCatalogue
from nlosfw.common.errors import ConfigError
from nlosfw.image.interface import Imager
from nlosfw.model.interface import FieldModel
from nlosfw.pipeline.settings import NO_MODEL, RunSettings, SplitSettings, StopAfter, run_settings
from nlosfw.plugins import PluginHost, PluginKind
from nlosfw.simulate.interface import Simulator
from nlosfw.simulate.scene import Scene, scene_from_config
from nlosfw.transform.interface import PhasorTransform

P = TypeVar("P")

#: A run's resolved configuration as plain data (what config.yaml holds).
PlainConfig = Mapping[str, object]


@dataclass(frozen=True, eq=False)
class Planned(Generic[P]):
    """One plugin a run uses: its name, the instance built from its options, and
    ``distribution==version`` (part of cache keys: a plugin upgrade invalidates them)."""

    name: str
    plugin: P
    version: str


@dataclass(frozen=True, eq=False)
class PlannedModel:
    """One field model of the run: its role (``source``: ``model``, ``interp`` or a
    ``compare`` label), its plugin and the instance that will be fitted."""

    source: str
    name: str
    model: FieldModel


@dataclass(frozen=True, eq=False)
class RunPlan:
    """A run's settings and plugins, checked and built."""

    config: PlainConfig
    """The resolved configuration (written to config.yaml, hashed for resumed sweeps)."""
    settings: RunSettings
    transform: Planned[PhasorTransform]
    imager: Planned[Imager]
    models: tuple[PlannedModel, ...]
    """The selected model, the interp baseline and every ``compare`` model, in that order."""
    formats: FormatCatalogue
    """The installed capture formats (a capture file, a background)."""
    simulator: Planned[Simulator] | None = None
    """The simulator of a simulated capture (None for a capture file)."""
    scene: Scene | None = None
    """The scene of a simulated capture (None for a capture file)."""
    format_versions: Mapping[str, str] | None = None
    """``distribution==version`` of each capture format, by name."""

    def selected(self, group: str) -> str | None:
        """The plugin or scene name the configuration selects in ``group`` (None: none)."""
        node = self.config.get(group)
        name = node.get("name") if isinstance(node, Mapping) else None
        return None if name is None else str(name)

    @property
    def images_only(self) -> bool:
        """``model=none``: the run images the capture alone (no split, no field model)."""
        return self.selected("model") == NO_MODEL

    def used_config(self) -> PlainConfig:
        """The configuration without what the run does not use: a run from a file has no
        scene and no simulator (their defaults would mislabel it)."""
        if self.settings.capture.path is None:
            return self.config
        return {k: v for k, v in self.config.items() if k not in ("scene", "simulator")}


def plugin_options(config: PlainConfig, group: str) -> tuple[str, dict[str, object]]:
    """The plugin ``config[group]`` selects and its options (a one-line error when none)."""
    node = config.get(group)
    options = dict(node) if isinstance(node, Mapping) else {}
    name = options.pop("name", None)
    if not name:
        raise ConfigError(group, "no plugin selected")
    return str(name), {str(k): v for k, v in options.items()}


def plugin_version(host: PluginHost, kind: PluginKind, name: str) -> str:
    """``distribution==version`` of a plugin (``==unknown`` when not installed as one)."""
    dist = host.registry.get(kind, name).distribution
    try:
        return f"{dist}=={version(dist)}"
    except PackageNotFoundError:
        return f"{dist}==unknown"


def make_plan(config: PlainConfig, host: PluginHost) -> RunPlan:
    """The plan of the run ``config`` describes, its plugins built from ``host``."""
    settings = run_settings(config)
    check_model_choice(config, settings)
    registry = host.registry

    def chosen(kind: PluginKind) -> tuple[str, dict[str, object], str]:
        name, options = plugin_options(config, kind.value)
        return name, options, plugin_version(host, kind, name)

    t_name, t_options, t_version = chosen(PluginKind.PHASOR_TRANSFORM)
    i_name, i_options, i_version = chosen(PluginKind.IMAGER)
    models = tuple(PlannedModel(source, name, registry.create(PluginKind.FIELD_MODEL, name,
                                                              options))
                   for source, (name, options) in field_models(config, settings).items())
    simulator, scene = None, None
    if settings.capture.path is None:
        s_name, s_options, s_version = chosen(PluginKind.SIMULATOR)
        simulator = Planned(s_name, registry.create(PluginKind.SIMULATOR, s_name, s_options),
                            s_version)
        scene = scene_from_config(config["scene"])
    formats = {name: plugin_version(host, PluginKind.CAPTURE_FORMAT, name)
               for name in registry.names(PluginKind.CAPTURE_FORMAT)}
    imager = registry.create(PluginKind.IMAGER, i_name, i_options)
    check_reference_choice(settings, i_name, imager.full_grid_only)
    return RunPlan(
        config=config, settings=settings,
        transform=Planned(t_name, registry.create(PluginKind.PHASOR_TRANSFORM, t_name,
                                                  t_options), t_version),
        imager=Planned(i_name, imager, i_version),
        models=models, formats=host.capture_formats(), simulator=simulator, scene=scene,
        format_versions=formats)


def check_model_choice(config: PlainConfig, settings: RunSettings) -> None:
    """A one-line ConfigError for options that ``model=none`` (no field model: the capture
    is imaged alone) cannot honour: a split, ``compare`` models, stopping after fit or
    predict."""
    node = config.get("model")
    if not isinstance(node, Mapping) or node.get("name") != NO_MODEL:
        return
    if settings.compare:
        raise ConfigError("compare", "model=none fits no field model, so there is nothing to "
                          "compare; select a model (model=interp) or leave compare empty")
    if settings.split != SplitSettings():
        raise ConfigError("split", "model=none images the whole capture and splits nothing; "
                          "leave the split options at their defaults or select a model "
                          "(model=interp)")
    if settings.stop_after in (StopAfter.fit, StopAfter.predict):
        raise ConfigError("stop_after", f"model=none fits and predicts nothing; stop after "
                          f"capture, transform or reconstruct, not {settings.stop_after}")


def check_reference_choice(settings: RunSettings, imager: str, time_domain: bool) -> None:
    """A one-line ConfigError for ``reconstruction.histogram_reference=true`` with an imager
    that images a band (``time_domain``: its ``full_grid_only``, as lct, fk and fbp)."""
    if settings.reconstruction.histogram_reference and not time_domain:
        raise ConfigError("reconstruction.histogram_reference", f"true images the histograms "
                          f"with a time-domain imager (lct, fk or fbp), and imager {imager} "
                          "images a band of frequencies; select one or leave it null")


def field_models(config: PlainConfig, settings: RunSettings
                 ) -> dict[str, tuple[str, dict[str, object]]]:
    """(plugin, options) by source: the selected model, the interp baseline (unless it is
    the model) and each ``compare`` label; none for ``model=none``."""
    name, options = plugin_options(config, "model")
    if name == NO_MODEL:
        return {}
    models = {"model": (name, options)} if name != "interp" else {}
    models["interp"] = (name, options) if name == "interp" else ("interp", {})
    for label, extra in settings.compare.items():
        rest = {str(k): v for k, v in extra.items() if k != "name"}
        models[label] = (str(extra["name"]), rest)
    return models

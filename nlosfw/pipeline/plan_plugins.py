"""The plugins of a run's plan: checked (installed, importable, their options valid, what
their options name outside themselves), built from the registry, and what each declares
it needs read once (:class:`~nlosfw.model.ModelNeeds`, :class:`~nlosfw.image.ImagerNeeds`).

Part of :func:`nlosfw.pipeline.make_plan`: nothing else reads a plugin's declared needs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import Generic, TypeVar

from nlosfw.common.errors import ConfigError, PluginError
from nlosfw.image.interface import Imager, ImagerNeeds
from nlosfw.model.interface import FieldModel, FieldModelConfig, ModelNeeds
from nlosfw.pipeline.settings import NO_MODEL, RunSettings
from nlosfw.plugins import RUN_KINDS, PluginHost, PluginKind, PluginSpec, check_device

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
    ``compare`` label), its plugin, the instance that will be fitted and what its fit
    needs of the run."""

    source: str
    name: str
    model: FieldModel
    needs: ModelNeeds = ModelNeeds()

    @property
    def option(self) -> str:
        """The configuration's name of its options: ``model`` (the selected model and the
        interp baseline) or ``compare.<label>``."""
        return "model" if self.source in ("model", "interp") else f"compare.{self.source}"


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


def check_plugin(spec: PluginSpec, what: str) -> None:
    """A one-line PluginError, before the run starts, when the plugin ``what`` names needs
    packages that are not installed (with the command that installs them) or its code
    cannot be imported."""
    command = spec.install_command()
    if command:
        raise PluginError(f"{what} '{spec.name}' needs packages that are not installed; "
                          f"run: {command}")
    check_imports(spec)


def check_imports(spec: PluginSpec) -> None:
    """A one-line PluginError when a selected plugin's code cannot be imported (a typo in its
    factory path, an import error, a missing dependency), before the run starts."""
    reason = spec.import_problem()
    if reason:
        raise PluginError(f"{reason} (see: python -m nlosfw plugins {spec.qualified_name})")


def checked_plugins(config: PlainConfig, host: PluginHost) -> dict[str, tuple[str, object]]:
    """(name, validated config) of the plugin each group of a run selects (every kind a run
    uses, the simulator too; none for ``model=none``): installed, importable, its options
    valid, and a model's :meth:`~nlosfw.model.FieldModel.check_config` passed."""
    chosen: dict[str, tuple[str, object]] = {}
    for kind in RUN_KINDS:
        name, options = plugin_options(config, kind.value)
        if kind is PluginKind.FIELD_MODEL and name == NO_MODEL:
            continue
        spec = host.registry.get(kind, name)
        check_plugin(spec, f"{kind.value} plugin")
        settings = spec.make_config(options)
        if kind is PluginKind.FIELD_MODEL:
            spec.load().check_config(settings)
        if kind is PluginKind.IMAGER and hasattr(settings, "device"):
            check_device(settings.device, host.registry.array_backends)
        chosen[kind.value] = (name, settings)
    return chosen


def model_needs(config: object) -> ModelNeeds:
    """What a model's fit needs of the run, as its config declares it (a config that does
    not derive from :class:`~nlosfw.model.FieldModelConfig` declares nothing)."""
    if not isinstance(config, FieldModelConfig):
        return ModelNeeds()
    return ModelNeeds(photon_counts=bool(config.uses_photon_counts),
                      noise_variance=bool(config.uses_noise_variance))


def imager_needs(imager: Imager) -> ImagerNeeds:
    """What the imager needs of the fields it images, as its class declares it."""
    return ImagerNeeds(time_domain=bool(type(imager).full_grid_only))


def planned_models(config: PlainConfig, settings: RunSettings, host: PluginHost,
                   selected: object) -> tuple[PlannedModel, ...]:
    """The run's field models built: the selected one (its config ``selected``, checked
    already), the interp baseline (unless it is the model) and each ``compare`` label
    (checked here: its errors name ``compare.<label>.<option>``), each with its needs; a
    ConfigError for ``split.spectral`` when a model takes the photon counts while
    frequencies are held out."""
    name, _ = plugin_options(config, "model")
    if name == NO_MODEL:
        return ()
    registry = host.registry
    built: list[PlannedModel] = []
    if name != "interp":
        built.append(_planned("model", name, registry.create(PluginKind.FIELD_MODEL, name,
                                                             selected), settings, "model"))
    interp = selected if name == "interp" else None
    built.append(_planned("interp", "interp", registry.create(PluginKind.FIELD_MODEL, "interp",
                                                              interp), settings, "model"))
    for label, extra in settings.compare.items():
        rest = {str(k): v for k, v in extra.items() if k != "name"}
        spec = registry.get(PluginKind.FIELD_MODEL, str(extra["name"]))
        check_plugin(spec, f"compare.{label}: model plugin")
        try:
            model_config = spec.make_config(rest)
            spec.load().check_config(model_config)
        except ConfigError as err:
            raise ConfigError(f"compare.{label}.{err.option.split('.', 1)[-1]}",
                              err.problem) from None
        model = registry.create(PluginKind.FIELD_MODEL, spec.name, model_config)
        built.append(_planned(label, spec.name, model, settings, f"compare.{label}"))
    return tuple(built)


def _planned(source: str, name: str, model: FieldModel, settings: RunSettings,
             option: str) -> PlannedModel:
    needs = model_needs(model.config)
    if needs.photon_counts and settings.split.spectral != "none":
        raise ConfigError("split.spectral", f"{option}: the photon counts' likelihood sees "
                          "every frequency of the counts, so no frequency can be held out; "
                          f"set split.spectral=none (got {settings.split.spectral})")
    return PlannedModel(source=source, name=name, model=model, needs=needs)

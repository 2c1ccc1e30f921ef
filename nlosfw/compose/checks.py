"""A run's configuration checked before anything is written.

The configuration is composed with Hydra's compose API and validated: every group
choice, every plugin option, the scene, the run settings, the memory the run needs (one
composition per swept value); the output directories are checked too (writable, no live
run or earlier run in the way, a resumed sweep's configuration unchanged: see
:mod:`nlosfw.compose.output_dirs`). A mistake ends with one line naming the option.
"""

from __future__ import annotations

import copy
import itertools
import logging
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from nlosfw.capture.data import Capture
from nlosfw.capture.photon_counts import photon_counts
from nlosfw.capture.source import file_transient_shape, load_file_capture
from nlosfw.common.errors import ConfigError, NlosfwError, PluginError, one_line
from nlosfw.common.schema import is_schema_node, problem
from nlosfw.compose.capture_checks import check_capture_kind, check_scene_preprocessing
from nlosfw.compose.output_dirs import check_output_dirs
from nlosfw.compose.store import hydra_session
from nlosfw.evaluation.count_splitting import OPTION as SPLIT_OPTION
from nlosfw.evaluation.count_splitting import check_count_split
from nlosfw.evaluation.noise_floor import DFT_TRANSFORMS, kernel_power
from nlosfw.pipeline.budget import check_memory
from nlosfw.pipeline.model_budget import plugin_requires
from nlosfw.pipeline.plan import check_model_choice, check_reference_choice
from nlosfw.pipeline.settings import (
    NO_MODEL,
    OPTIONAL_GROUPS,
    SELECTOR_GROUPS,
    RunSettings,
    run_settings,
)
from nlosfw.plugins import RUN_KINDS, PluginHost, PluginKind, PluginSpec
from nlosfw.simulate.geometry import validate_scene
from nlosfw.simulate.scene import NoiseModel, scene_from_config
from nlosfw.transform.counts import check_counts_times

if TYPE_CHECKING:
    from hydra.core.config_loader import ConfigLoader
    from hydra.core.override_parser.types import Override
    from omegaconf import DictConfig

log = logging.getLogger(__name__)

_PLUGIN_GROUPS = tuple(k.value for k in RUN_KINDS)
#: The plugins that take the capture as it is: they must take its kind.
_TAKE_THE_CAPTURE = (PluginKind.PHASOR_TRANSFORM, PluginKind.IMAGER)
_MAX_PREFLIGHT_COMPOSITIONS = 64


def preflight(overrides: Sequence[str], host: PluginHost, config_name: str = "config",
              multirun: bool = False, outputs: bool = True) -> None:
    """Compose and validate the config for every swept value; raise a one-line NlosfwError.

    Swept values come from ``overrides`` and, for a multirun, from the
    ``hydra.sweeper.params`` a preset or primary config declares. With ``outputs`` the
    output directories are checked too.
    """
    from hydra import compose
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    try:
        parsed = OverridesParser.create().parse_overrides(list(overrides))
    except HydraException as err:
        raise ConfigError("", f"cannot parse overrides: {one_line(err, whole=True)}") from None
    fixed, sweeps = [], []
    for ov, text in zip(parsed, overrides, strict=True):
        if ov.is_sweep_override():
            sweeps.append((ov.get_key_element(), _values(ov)))
        else:
            fixed.append(text)
    with hydra_session():
        loader = GlobalHydra.instance().config_loader()
        for key, values in [(o.key_or_group, _values(o)) for o in parsed]:
            _check_group_choice(key, values, loader, host)

        done: dict[tuple[tuple[str, ...], bool], DictConfig] = {}

        def composed(combo: list[str], with_hydra: bool = False) -> DictConfig:
            """The config of ``combo``, composed once per preflight (a copy each time:
            a single run asks for the same composition four times, 0.6 s each)."""
            key = (tuple(combo), with_hydra)
            if key not in done:
                try:
                    done[key] = compose(config_name=config_name, overrides=combo,
                                        return_hydra_config=with_hydra)
                except (HydraException, OmegaConfBaseException) as err:
                    raise composition_error(err) from None
            return copy.deepcopy(done[key])

        first = fixed + [f"{key}={values[0]}" for key, values in sweeps if values]
        declared: dict[str, object] = {}
        if multirun:
            given = {o.get_key_element() for o in parsed}
            declared = dict(composed(first, with_hydra=True).hydra.sweeper.params or {})
            for key, value in declared.items():
                if key in given:
                    continue
                (ov,) = OverridesParser.create().parse_overrides([f"{key}={value}"])
                _check_group_choice(ov.key_or_group, _values(ov), loader, host)
                sweeps.append((key, _values(ov)))
        combos = itertools.product(*[[f"{key}={v}" for v in values] for key, values in sweeps])
        total = math.prod(len(values) for _, values in sweeps)
        chdir = bool(composed(first, with_hydra=True).hydra.job.get("chdir", False))
        for combo in itertools.islice(combos, _MAX_PREFLIGHT_COMPOSITIONS):
            cfg = composed(fixed + list(combo))
            if chdir:
                _refuse_relative_inputs(cfg)
            validate_config(cfg, host)
        if total > _MAX_PREFLIGHT_COMPOSITIONS:
            log.warning("checked the first %d of %d sweep combinations before starting; "
                        "the others are checked when their run starts",
                        _MAX_PREFLIGHT_COMPOSITIONS, total)
        if outputs:
            check_output_dirs(composed, list(overrides), first,
                              [f"{k}={v}" for k, v in declared.items()], multirun)


def composition_error(err: Exception, host: PluginHost | None = None) -> NlosfwError:
    """Hydra's or OmegaConf's error while composing, as one line naming the option (with
    ``host``, a plugin that is registered but broken says why)."""
    from hydra.errors import MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(err, MissingConfigException) and "/" in (err.missing_cfg_file or ""):
        group, _, name = str(err.missing_cfg_file).rpartition("/")
        if host is not None and group in _PLUGIN_GROUPS and (group, name) in host.registry:
            try:
                _check_imports(host.registry.get(group, name))
            except PluginError as broken:
                return broken
        if group in SELECTOR_GROUPS:
            return _unknown_choice(group, name, sorted(err.options or []))
    cause = err if isinstance(err, OmegaConfBaseException) else err.__cause__
    if isinstance(cause, OmegaConfBaseException) and cause.full_key:
        key, what = str(cause.full_key), problem(cause, cause.value)
        override = re.match(r"(?:Error merging override |Could not override ')([^=']+)", str(err))
        dotted = re.sub(r"\[(\d+)\]", r".\1", key)             # geometry[0] -> geometry.0
        if override and not (dotted.startswith(override.group(1))
                             or override.group(1).startswith(dotted)):
            # OmegaConf names a key inside a merged value relative to that value
            return ConfigError(override.group(1), f"{key}: {what}")
        return ConfigError(key, what)
    return ConfigError("", one_line(err, whole=True))


def _refuse_relative_inputs(cfg: Mapping[str, object]) -> None:
    """With ``hydra.job.chdir=true`` the run starts in its run directory, where a relative
    input path would name another file: refuse it naming the option."""
    capture = cfg.get("capture")
    if not isinstance(capture, Mapping):
        return
    for name in ("path", "background", "tofgrid"):
        value = capture.get(name)
        if isinstance(value, str) and value and not value.startswith(("/", "~")):
            raise ConfigError(f"capture.{name}", f"'{value}' is a relative path, but "
                              "hydra.job.chdir=true runs in the run directory, where it names "
                              "another file; give an absolute path")


def validate_config(cfg: Mapping[str, object], host: PluginHost) -> None:
    """Check a composed config: plugin names, installed dependencies, options, scene,
    settings, the memory it needs, and its capture file or the files it names."""
    settings = run_settings(cfg)
    check_model_choice(cfg, settings)
    counts_needed = False           # a model's likelihood needs the field's Poisson variance
    times_needed = False            # or the counts themselves, in the capture's own times
    transform_config: object = None
    for group in _PLUGIN_GROUPS:
        node = cfg.get(group)
        if not isinstance(node, Mapping) or not node:
            raise ConfigError(group, "no plugin selected")
        if group == PluginKind.FIELD_MODEL.value and node.get("name") == NO_MODEL:
            continue  # model=none: no field model to check
        spec = host.registry.get(group, str(node.get("name")))
        _check_plugin(spec, f"{group} plugin")
        config = spec.make_config(_plugin_options(node, spec.config_class()))
        if group == PluginKind.FIELD_MODEL.value:
            _check_model_config(spec, config)
        counts_needed |= _needs_counts(config, settings, "model")
        times_needed |= bool(getattr(config, "uses_photon_counts", False))
        if group == PluginKind.PHASOR_TRANSFORM.value:
            transform_config = config
        if group == PluginKind.IMAGER.value:
            check_reference_choice(settings, spec.name,
                                   bool(getattr(spec.load(), "full_grid_only", False)))
    for label, options in settings.compare.items():
        rest = dict(options)
        spec = host.registry.get(PluginKind.FIELD_MODEL, str(rest.pop("name")))
        _check_plugin(spec, f"compare.{label}: model plugin")
        try:
            config = spec.make_config(rest)
            _check_model_config(spec, config)
        except ConfigError as err:
            raise ConfigError(f"compare.{label}.{err.option.split('.', 1)[-1]}",
                              err.problem) from None
        counts_needed |= _needs_counts(config, settings, f"compare.{label}")
        times_needed |= bool(getattr(config, "uses_photon_counts", False))
    formats = host.capture_formats()
    # before anything sized by the configuration is allocated
    check_memory(cfg, file_shape=lambda path: file_transient_shape(
        path, settings.capture.format, formats), requires=plugin_requires(host))
    if settings.capture.path is None:
        scene = validate_scene(scene_from_config(cfg.get("scene"))).scene
        if scene.noise.model != NoiseModel.poisson:   # what needs counts is refused here
            if settings.split.count_splitting:
                raise ConfigError(SPLIT_OPTION, "count splitting needs photon counts, but "
                                  "the simulated capture has no photon noise; set "
                                  "scene.noise.model=poisson")
            if settings.capture.pileup_pulses is not None:
                raise ConfigError("capture.pileup_pulses", "the pile-up correction needs "
                                  "photon counts, but the simulated capture has no photon "
                                  "noise; set scene.noise.model=poisson or leave it null")
            if counts_needed:
                raise ConfigError("model.likelihood", "a Poisson likelihood needs photon "
                                  "counts, but the simulated capture has none; set "
                                  "scene.noise.model=poisson or use least_squares")
        simulator_node = cfg.get("simulator")
        if not isinstance(simulator_node, Mapping):
            raise ConfigError("simulator", "no plugin selected")
        simulator = host.registry.get(PluginKind.SIMULATOR, str(simulator_node.get("name")))
        simulator.create(_plugin_options(simulator_node, simulator.config_class())
                         ).check(scene)
        layout = check_scene_preprocessing(scene, settings.capture.options, formats)
        check_capture_kind(layout, cfg, host, f"scene {scene.name}'s capture "
                           f"(scene.capture.type={scene.capture.type})",
                           (PluginKind.SIMULATOR, *_TAKE_THE_CAPTURE))
        return
    # a malformed file, a wrong format or an option that does not fit the file must fail
    # here, before any output exists
    loaded = load_file_capture(settings.capture, formats)
    check_capture_kind(loaded.prepared.capture, cfg, host, str(loaded.path))
    if settings.split.count_splitting:  # it needs photon counts: refused here, not later
        check_count_split(loaded.prepared.capture, settings.split.count_splitting_seed,
                          str(loaded.path))
        _check_noise_floor(cfg, host, loaded.prepared.capture)
    if counts_needed:
        likelihood = ("model.likelihood", "the Poisson likelihood")
        photon_counts(loaded.prepared.capture, str(loaded.path), *likelihood)
        if times_needed:
            check_counts_times(loaded.prepared.capture.geometry, transform_config,
                               str(loaded.path))
        _check_noise_floor(cfg, host, loaded.prepared.capture, *likelihood)


def _check_model_config(spec: PluginSpec, config: object) -> None:
    """The model plugin's own checks of what its options name (``check_config``)."""
    check = getattr(spec.load(), "check_config", None)
    if callable(check):
        check(config)


def _needs_counts(config: object, settings: RunSettings, option: str) -> bool:
    """Whether a model's likelihood needs the capture's photon counts; a ConfigError for
    ``split.spectral`` when it takes the counts themselves while frequencies are held out
    (the counts hold every frequency)."""
    if getattr(config, "uses_photon_counts", False) and settings.split.spectral != "none":
        raise ConfigError("split.spectral", f"{option}: the photon counts' likelihood sees "
                          "every frequency of the counts, so no frequency can be held out; "
                          f"set split.spectral=none (got {settings.split.spectral})")
    return bool(getattr(config, "uses_noise_variance", False)
                or getattr(config, "uses_photon_counts", False))


def _check_noise_floor(cfg: Mapping[str, object], host: PluginHost, capture: Capture,
                       option: str = SPLIT_OPTION, purpose: str = "count splitting"
                       ) -> None:
    """Count splitting's noise floor (and a Poisson likelihood) needs a DFT-like transform:
    the built-in ones are; another is probed on the capture (a ConfigError for ``option``
    when it is not)."""
    node = cfg.get("transform")
    name = str(node.get("name")) if isinstance(node, Mapping) else ""
    if name in DFT_TRANSFORMS or not isinstance(node, Mapping):
        return
    spec = host.registry.get(PluginKind.PHASOR_TRANSFORM, name)
    kernel_power(spec.create(_plugin_options(node, spec.config_class())), capture, name,
                 option, purpose)


def _check_plugin(spec: PluginSpec, what: str) -> None:
    """A one-line PluginError, before the run starts, when the plugin ``what`` names needs
    packages that are not installed (with the command that installs them) or its code
    cannot be imported."""
    command = spec.install_command()
    if command:
        raise PluginError(f"{what} '{spec.name}' needs packages that are not installed; "
                          f"run: {command}")
    _check_imports(spec)


def _check_imports(spec: PluginSpec) -> None:
    """A one-line PluginError when a selected plugin's code cannot be imported (a typo in its
    factory path, an import error, a missing dependency), before the run starts."""
    reason = spec.import_problem()
    if reason:
        raise PluginError(f"{reason} (see: python -m nlosfw plugins {spec.qualified_name})")


def _plugin_options(node: Mapping[str, object], config_class: type) -> Mapping[str, object]:
    """A plugin's options from its composed group node: the node itself when Hydra composed
    it from the plugin's entry (its ``name`` is part of that schema), else without ``name``."""
    if is_schema_node(node, config_class):
        return node
    return {k: v for k, v in node.items() if k != "name"}


def _values(override: Override) -> list[str]:
    if override.is_sweep_override():
        return [str(v) for v in override.sweep_string_iterator()]
    value = override.value()
    return [] if value is None else [str(value)]


def _check_group_choice(key: str, values: list[str], loader: ConfigLoader,
                        host: PluginHost) -> None:
    """Refuse an unknown scene, plugin or preset name, and a registered plugin whose config
    could not be stored because it is broken."""
    if key not in SELECTOR_GROUPS:
        return
    options = loader.get_group_options(key)
    for value in values:
        if value in ("null", "None") and key in OPTIONAL_GROUPS:
            continue
        if value not in options:
            if key in _PLUGIN_GROUPS and (key, value) in host.registry:
                _check_imports(host.registry.get(key, value))
            raise _unknown_choice(key, value, sorted(options))


def _unknown_choice(group: str, value: str, options: list[str]) -> ConfigError:
    noun = f"{group} plugin" if group in _PLUGIN_GROUPS else group
    hint = " (is its plugin installed? see: python -m nlosfw plugins)" if (
        group in _PLUGIN_GROUPS) else ""
    valid = ", ".join(options) or "(none)"
    return ConfigError("", f"unknown {noun} '{value}'; valid: {valid}{hint}")

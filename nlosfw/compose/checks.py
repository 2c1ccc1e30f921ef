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

from nlosfw.capture.source import CaptureSource
from nlosfw.common.errors import ConfigError, NlosfwError, PluginError, one_line
from nlosfw.common.schema import problem
from nlosfw.compose.output_dirs import check_output_dirs
from nlosfw.compose.store import hydra_session
from nlosfw.pipeline.plan import PlainConfig, RunPlan, make_plan
from nlosfw.pipeline.plan_plugins import check_imports
from nlosfw.pipeline.settings import OPTIONAL_GROUPS, SELECTOR_GROUPS, run_settings
from nlosfw.plugins import RUN_KINDS, PluginHost

if TYPE_CHECKING:
    from hydra.core.config_loader import ConfigLoader
    from hydra.core.override_parser.types import Override
    from omegaconf import DictConfig

log = logging.getLogger(__name__)

_PLUGIN_GROUPS = tuple(k.value for k in RUN_KINDS)
_MAX_PREFLIGHT_COMPOSITIONS = 64


def preflight(overrides: Sequence[str], host: PluginHost, config_name: str = "config",
              multirun: bool = False, outputs: bool = True,
              composed_run: DictConfig | None = None) -> RunPlan | None:
    """Compose and validate the config for every swept value; raise a one-line NlosfwError.

    Swept values come from ``overrides`` and, for a multirun, from the
    ``hydra.sweeper.params`` a preset or primary config declares. With ``outputs`` the
    output directories are checked too. Validating a configuration is making its plan
    (:func:`validate_config`): for a single run the plan is returned, for a multirun every
    combination's plan is made and discarded (each job makes its own) and None returned.
    ``composed_run``: the configuration of a single run as Hydra composed it (its ``hydra``
    node included), used as it is instead of being composed again.
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

        if composed_run is not None and not multirun:   # Hydra's own composition
            done[(tuple(fixed), True)] = composed_run
            done[(tuple(fixed), False)] = _without_hydra(composed_run)

        def composed(combo: list[str], with_hydra: bool = False) -> DictConfig:
            """The config of ``combo``, composed once per preflight (a copy each time:
            a single run asks for the same composition several times, each slow)."""
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
        plan = None
        for combo in itertools.islice(combos, _MAX_PREFLIGHT_COMPOSITIONS):
            cfg = composed(fixed + list(combo))
            if chdir:
                _refuse_relative_inputs(run_settings(task_config(cfg)).capture)
            plan = validate_config(cfg, host)
        if total > _MAX_PREFLIGHT_COMPOSITIONS:
            log.warning("checked the first %d of %d sweep combinations before starting; "
                        "the others are checked when their run starts",
                        _MAX_PREFLIGHT_COMPOSITIONS, total)
        if outputs:
            check_output_dirs(composed, list(overrides), first,
                              [f"{k}={v}" for k, v in declared.items()], multirun)
    return None if multirun else plan


def _without_hydra(cfg: DictConfig) -> DictConfig:
    """A copy of ``cfg`` without Hydra's own node (the job's configuration)."""
    from omegaconf import open_dict

    task = copy.deepcopy(cfg)
    with open_dict(task):
        task.pop("hydra", None)
    return task


def composition_error(err: Exception, host: PluginHost | None = None) -> NlosfwError:
    """Hydra's or OmegaConf's error while composing, as one line naming the option (with
    ``host``, a plugin that is registered but broken says why)."""
    from hydra.errors import MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(err, MissingConfigException) and "/" in (err.missing_cfg_file or ""):
        group, _, name = str(err.missing_cfg_file).rpartition("/")
        if host is not None and group in _PLUGIN_GROUPS and (group, name) in host.registry:
            try:
                check_imports(host.registry.get(group, name))
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


def _refuse_relative_inputs(capture: CaptureSource) -> None:
    """With ``hydra.job.chdir=true`` the run starts in its run directory, where a relative
    input path would name another file: refuse it naming the option."""
    for name, value in (("path", capture.path), ("background", capture.background),
                        ("tofgrid", capture.tofgrid)):
        if isinstance(value, str) and value and not value.startswith(("/", "~")):
            raise ConfigError(f"capture.{name}", f"'{value}' is a relative path, but "
                              "hydra.job.chdir=true runs in the run directory, where it names "
                              "another file; give an absolute path")


def validate_config(cfg: Mapping[str, object] | DictConfig, host: PluginHost) -> RunPlan:
    """Check a composed config by making its plan (:func:`~nlosfw.pipeline.make_plan`, the
    one validator: plugin names, installed dependencies, options, scene, settings, the
    memory it needs, and its capture file, read once, or the files it names)."""
    return make_plan(task_config(cfg), host)


def task_config(cfg: Mapping[str, object] | DictConfig) -> PlainConfig:
    """The resolved configuration of a run as plain data: a composed config without Hydra's
    own node (as Hydra hands it to the job), or a plain mapping as it is."""
    from omegaconf import DictConfig, OmegaConf, open_dict

    if not isinstance(cfg, DictConfig):
        return cfg
    if "hydra" in cfg:
        cfg = copy.deepcopy(cfg)
        with open_dict(cfg):
            del cfg["hydra"]
    plain = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    if not isinstance(plain, dict):  # a composed config is a mapping
        raise ConfigError("", "the composed configuration is not a mapping")
    return {str(k): v for k, v in plain.items()}


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
                check_imports(host.registry.get(key, value))
            raise _unknown_choice(key, value, sorted(options))


def _unknown_choice(group: str, value: str, options: list[str]) -> ConfigError:
    noun = f"{group} plugin" if group in _PLUGIN_GROUPS else group
    hint = " (is its plugin installed? see: python -m nlosfw plugins)" if (
        group in _PLUGIN_GROUPS) else ""
    valid = ", ".join(options) or "(none)"
    return ConfigError("", f"unknown {noun} '{value}'; valid: {valid}{hint}")

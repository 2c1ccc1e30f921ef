"""The Hydra application behind ``python -m nlosfw``.

Three things happen before Hydra takes over:

1. the run's schema (:class:`~nlosfw.app.settings.RunConfig`) and one config group entry
   per registered plugin (``model=siren_torch``), made from the plugin's own config
   dataclass, go into Hydra's ConfigStore: Hydra checks every name and type as it
   composes, and a third-party plugin is selectable without touching ``conf/``;
2. ``+group=name`` is accepted for the selector groups (``+simulator=embree``):
   Hydra refuses ``+`` for a group that already has a default, so the ``+`` is
   dropped there and the override selects the option as ``group=name`` does;
3. the configuration is composed with Hydra's compose API and validated (every group
   choice, every plugin option, the scene, the run settings, the memory the run needs;
   one composition per swept value), and the output directories are checked (writable,
   no live run or earlier run in the way, a resumed sweep's configuration unchanged: see
   :mod:`nlosfw.app.output_dirs`), so a mistake ends with one line and exit status 2
   before any output exists.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import logging
import math
import re
import sys
import uuid
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any, NoReturn

from nlosfw.app.budget import check_memory
from nlosfw.app.output_dirs import check_output_dirs
from nlosfw.app.settings import OPTIONAL_GROUPS, SELECTOR_GROUPS, RunConfig, run_settings
from nlosfw.common.errors import ConfigError, NlosfwError, PluginError, one_line
from nlosfw.common.schema import is_schema_node, problem, schema_class
from nlosfw.plugins import PluginHost, PluginSpec
from nlosfw.plugins.kinds import RUN_KINDS

log = logging.getLogger(__name__)

_PLUGIN_GROUPS = tuple(k.value for k in RUN_KINDS)
_MAX_PREFLIGHT_COMPOSITIONS = 64

#: Name of the run's schema in Hydra's ConfigStore (the first entry of config.yaml's defaults).
RUN_SCHEMA = "nlosfw_run_schema"


def config_dir() -> Path:
    """The directory of ``config.yaml``: the installed ``nlosfw.conf`` package or ``conf/``."""
    try:
        path = Path(str(resources.files("nlosfw.conf")))
        if (path / "config.yaml").is_file():
            return path
    except (ModuleNotFoundError, TypeError):
        pass
    source_tree = Path(__file__).resolve().parents[2] / "conf"
    if (source_tree / "config.yaml").is_file():
        return source_tree
    raise PluginError("cannot find nlosfw's Hydra configs (package nlosfw.conf); reinstall "
                      "nlosfw with: pip install .")


def register_configs(host: PluginHost) -> None:
    """Store the run's schema and one entry per plugin of the kinds a run selects (group =
    plugin kind) in Hydra's ConfigStore; a plugin's entry is its config dataclass with the
    selector ``name``. Capture formats are chosen by ``capture.format`` instead."""
    from hydra.core.config_store import ConfigStore
    from omegaconf.errors import OmegaConfBaseException

    store = ConfigStore.instance()
    store.store(name=RUN_SCHEMA, node=schema_class(RunConfig), provider="nlosfw")
    for spec in host.registry.specs():
        if spec.kind not in RUN_KINDS:
            continue
        try:
            cls = spec.config_class()
            if "name" in {f.name for f in dataclasses.fields(cls)}:
                log.warning("plugin %s is not selectable: its config has a field 'name', which "
                            "is the group's plugin selector", spec.qualified_name)
                continue
            store.store(group=spec.kind.value, name=spec.name,
                        node=schema_class(cls, spec.name), provider=spec.distribution)
        except (NlosfwError, OmegaConfBaseException, TypeError) as err:
            log.warning("plugin %s has no usable config and is not selectable: %s",
                        spec.qualified_name, one_line(err))


def normalise_overrides(args: Sequence[str]) -> list[str]:
    """Turn ``+group=x`` / ``++group=x`` into ``group=x`` for the selector groups."""
    out = []
    for arg in args:
        stripped = arg.lstrip("+")
        key = stripped.split("=", 1)[0]
        if arg.startswith("+") and "=" in stripped and key in SELECTOR_GROUPS:
            out.append(stripped)
        else:
            out.append(arg)
    return out


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise ConfigError("", f"command line: {message}")


def parse_command_line(args: Sequence[str]) -> argparse.Namespace:
    """The flags and overrides of Hydra's command line (``hydra.main`` reads them again).

    nlosfw needs the overrides, the config name and whether it is a multirun, to compose
    and check the configuration before Hydra runs anything.
    """
    parser = _Parser(prog="python -m nlosfw", add_help=False, allow_abbrev=False)
    parser.add_argument("overrides", nargs="*")
    for flags in (["--help", "-h"], ["--hydra-help"], ["--version"], ["--resolve"],
                  ["--run", "-r"], ["--multirun", "-m"], ["--shell-completion", "-sc"]):
        parser.add_argument(*flags, action="store_true")
    for flags in (["--package", "-p"], ["--config-path", "-cp"], ["--config-name", "-cn"],
                  ["--config-dir", "-cd"], ["--experimental-rerun"]):
        parser.add_argument(*flags)
    parser.add_argument("--cfg", "-c", choices=["job", "hydra", "all"])
    parser.add_argument("--info", "-i", nargs="?", const="all",
                        choices=["all", "config", "defaults", "defaults-tree", "plugins",
                                 "searchpath"])
    parsed = parser.parse_intermixed_args(list(args))  # flags anywhere, as Hydra allows
    modes = [flag for flag, given in (("--run", parsed.run), ("--multirun", parsed.multirun),
                                      ("--cfg", parsed.cfg), ("--info", parsed.info),
                                      ("--shell-completion", parsed.shell_completion)) if given]
    if len(modes) > 1:
        raise ConfigError("", f"command line: {' and '.join(modes)} cannot be given together; "
                              "use one of --run, --multirun, --cfg, --info, --shell-completion")
    return parsed


def ensure_resolvers() -> None:
    """Register the ``nlosfw_run_id`` resolver (a short random id, fixed per process)."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver("nlosfw_run_id"):
        run_id = uuid.uuid4().hex[:6]
        OmegaConf.register_new_resolver("nlosfw_run_id", lambda: run_id)


def preflight(overrides: Sequence[str], host: PluginHost, config_name: str = "config",
              multirun: bool = False, outputs: bool = True) -> None:
    """Compose and validate the config for every swept value; raise a one-line NlosfwError.

    Swept values come from the command line and, for multirun, from the
    ``hydra.sweeper.params`` a preset or primary config declares. With ``outputs`` (a
    command that runs, not ``--cfg`` or ``--info``) the output directories are checked too.
    """
    from hydra import compose, initialize_config_dir
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
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3",
                                   job_name="nlosfw"):
            loader = GlobalHydra.instance().config_loader()
            for key, values in [(o.key_or_group, _values(o)) for o in parsed]:
                _check_group_choice(key, values, loader, host)

            def composed(combo: list[str], with_hydra: bool = False) -> Any:
                try:
                    return compose(config_name=config_name, overrides=combo,
                                   return_hydra_config=with_hydra)
                except (HydraException, OmegaConfBaseException) as err:
                    raise composition_error(err) from None

            first = fixed + [f"{key}={values[0]}" for key, values in sweeps if values]
            declared: dict[str, Any] = {}
            if multirun:
                given = {o.get_key_element() for o in parsed}
                declared = dict(composed(first, with_hydra=True).hydra.sweeper.params or {})
                for key, value in declared.items():
                    if key in given:
                        continue
                    (ov,) = OverridesParser.create().parse_overrides([f"{key}={value}"])
                    _check_group_choice(ov.key_or_group, _values(ov), loader, host)
                    sweeps.append((key, _values(ov)))
            combos = itertools.product(*[[f"{key}={v}" for v in values]
                                         for key, values in sweeps])
            total = math.prod(len(values) for _, values in sweeps)
            for combo in itertools.islice(combos, _MAX_PREFLIGHT_COMPOSITIONS):
                validate_config(composed(fixed + list(combo)), host)
            if total > _MAX_PREFLIGHT_COMPOSITIONS:
                log.warning("checked the first %d of %d sweep combinations before starting; "
                            "the others are checked when their run starts",
                            _MAX_PREFLIGHT_COMPOSITIONS, total)
            if outputs:
                check_output_dirs(composed, list(overrides), first,
                                  [f"{k}={v}" for k, v in declared.items()], multirun)
    finally:
        GlobalHydra.instance().clear()


def composition_error(err: Exception) -> NlosfwError:
    """Hydra's or OmegaConf's error while composing, as one line naming the option."""
    from hydra.errors import MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(err, MissingConfigException) and "/" in (err.missing_cfg_file or ""):
        group, _, name = str(err.missing_cfg_file).rpartition("/")
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


def validate_config(cfg: Any, host: PluginHost) -> None:
    """Check a composed config: plugin names, installed dependencies, options, scene, settings."""
    from nlosfw.simulate.scene import scene_from_config

    settings = run_settings(cfg)
    for group in _PLUGIN_GROUPS:
        node = cfg.get(group)
        if not node:
            raise ConfigError(group, "no plugin selected")
        spec = host.registry.get(group, str(node.get("name")))
        _check_plugin(spec, f"{group} plugin")
        spec.make_config(_plugin_options(node, spec.config_class()))
    for label, options in settings.compare.items():
        node = dict(options)
        spec = host.registry.get("model", str(node.pop("name")))
        _check_plugin(spec, f"compare.{label}: model plugin")
        try:
            spec.make_config(node)
        except ConfigError as err:
            raise ConfigError(f"compare.{label}.{err.option.split('.', 1)[-1]}",
                              err.problem) from None
    from nlosfw.app.capture_source import (
        check_files,
        file_transient_shape,
        load_file_capture,
        options_of,
    )

    # before anything sized by the configuration is allocated
    check_memory(cfg, file_shape=lambda path: file_transient_shape(
        path, settings.capture.format, host))

    if settings.capture.path is None:
        from nlosfw.simulate.geometry import validate_scene

        scene = validate_scene(scene_from_config(cfg.get("scene"))).scene
        simulator = host.registry.get("simulator", str(cfg.simulator.name))
        simulator.create(_plugin_options(cfg.simulator, simulator.config_class())
                         ).check_scene(scene)
        check_files(options_of(settings.capture), host)
        return
    # a malformed file, a wrong format or an option that does not fit the file must fail
    # here, before any output exists
    load_file_capture(settings.capture, host)


def main(argv: Sequence[str]) -> int:
    """Run the Hydra app with ``argv`` (without the program name); return the exit status."""
    import hydra

    from nlosfw.plugins import load_plugins

    argv = normalise_overrides(argv)
    args = parse_command_line(argv)
    host = load_plugins()
    register_configs(host)
    ensure_resolvers()
    if not (args.help or args.hydra_help or args.shell_completion or args.version):
        preflight(args.overrides, host, args.config_name or "config", bool(args.multirun),
                  outputs=not (args.cfg or args.info or args.resolve))
    decorated = hydra.main(config_path=str(config_dir()), config_name="config",
                           version_base="1.3")(_task)
    saved = sys.argv
    sys.argv = [saved[0] if saved else "nlosfw", *argv]
    try:
        decorated()
    finally:
        sys.argv = saved
    return 0


def _task(cfg: Any) -> float | None:
    """One Hydra job: the whole pipeline in its run directory."""
    from nlosfw.app.errors import report_user_error
    from nlosfw.app.pipeline import run_pipeline

    logging.captureWarnings(True)  # library warnings go to run.log, not the console
    try:
        return run_pipeline(cfg)
    except NlosfwError as err:
        report_user_error(err)
        raise SystemExit(err.exit_status) from None
    except MemoryError as err:  # the estimate let it through: still one line
        report_user_error(NlosfwError(f"out of memory ({one_line(err)}); make the run "
                                      "smaller (the sizes, or fewer sweep jobs at once)"))
        raise SystemExit(1) from None


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
    problem = spec.import_problem()
    if problem:
        raise PluginError(f"{problem} (see: python -m nlosfw plugins {spec.qualified_name})")


def _plugin_options(node: Any, config_class: type) -> Any:
    """A plugin's options from its composed group node: the node itself when Hydra composed
    it from the plugin's entry (its ``name`` is part of that schema), else without ``name``."""
    if is_schema_node(node, config_class):
        return node
    return {k: v for k, v in node.items() if k != "name"}


def _values(override: Any) -> list[str]:
    if override.is_sweep_override():
        return [str(v) for v in override.sweep_string_iterator()]
    value = override.value()
    return [] if value is None else [str(value)]


def _check_group_choice(key: str, values: list[str], loader: Any, host: PluginHost) -> None:
    """Refuse an unknown scene, plugin or preset name (``loader``: Hydra's ConfigLoader),
    and a registered plugin whose config could not be stored because it is broken."""
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


def compose_run_config(overrides: Sequence[str], host: PluginHost,
                       config_name: str = "config") -> dict[str, Any]:
    """The resolved configuration of one run, checked as the command line checks it.

    ``overrides`` are the command line's (``+group=name`` included); a sweep, a flag or
    a ``hydra.*`` setting is refused with a one-line :class:`ConfigError`.
    """
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    overrides = normalise_overrides([str(o) for o in overrides])
    for text in overrides:
        if text.startswith("-"):
            raise ConfigError("overrides", f"{text!r} is a command-line flag; give only "
                              "overrides such as 'model=interp'")
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException as err:
        raise ConfigError("overrides", f"cannot parse: {one_line(err, whole=True)}") from None
    for ov, text in zip(parsed, overrides, strict=True):
        if ov.is_sweep_override():
            raise ConfigError("overrides", f"{text!r} is a sweep; one call runs one "
                              "configuration: call it once per value, or sweep with "
                              "python -m nlosfw -m ...")
        if ov.key_or_group.split("/")[0].split(".")[0] == "hydra":
            raise ConfigError("overrides", f"{text!r}: Hydra's own settings do not apply here "
                              "(choose the run directory with output_dir=)")
    register_configs(host)
    ensure_resolvers()
    preflight(overrides, host, config_name)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3",
                                   job_name="nlosfw"):
            try:
                cfg = compose(config_name=config_name, overrides=list(overrides))
            except (HydraException, OmegaConfBaseException) as err:
                raise composition_error(err) from None
    finally:
        GlobalHydra.instance().clear()
    plain = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    assert isinstance(plain, dict)  # a composed config is a mapping
    return {str(k): v for k, v in plain.items()}

"""The output directories of a command, checked before Hydra writes anything into them.

Hydra creates a run's directory and writes ``.hydra/`` there before the job starts, so a
refusal found by the job itself (:mod:`nlosfw.pipeline.lifecycle`) would come after Hydra has
already overwritten an earlier run's ``.hydra/``. The preflight therefore resolves the
run directory (``hydra.run.dir``) or the sweep's job directories (``hydra.sweep.dir`` with
the default ``hydra.sweep.subdir``, jobs numbered as Hydra's basic sweeper numbers them)
and applies the same verdict first, and checks that they can be written at all.
"""

from __future__ import annotations

import itertools
import logging
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from nlosfw.common.errors import ConfigError
from nlosfw.common.files import unwritable_reason
from nlosfw.pipeline.files import PLANNED_NAMES
from nlosfw.pipeline.lifecycle import (
    HYDRA_FILES,
    check_outside_cache,
    inspect_run_dir,
    verdict,
)
from nlosfw.pipeline.settings import RunSettings, run_settings

if TYPE_CHECKING:  # hydra and omegaconf are imported when a check runs
    from hydra.core.override_parser.types import Override
    from omegaconf import DictConfig

log = logging.getLogger(__name__)

#: ``hydra.sweep.subdir`` as Hydra sets it by default: one directory per job number.
_DEFAULT_SUBDIR = "${hydra.job.num}"

Compose = Callable[[list[str], bool], "DictConfig"]
"""Composes the overrides (with Hydra's own config when the flag is true)."""


def check_output_dirs(compose: Compose, overrides: Sequence[str], first: Sequence[str],
                      sweep_params: Sequence[str], multirun: bool) -> None:
    """Refuse (one-line :class:`ConfigError`) an unwritable output location, a run directory
    that holds a live run or files in the way, or a sweep resumed with another
    configuration. ``overrides`` are the command's overrides, ``first`` the same with the
    first value of each swept one, ``sweep_params`` the ``hydra.sweeper.params`` a preset
    declares (as ``key=values``)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    cfg = compose(list(first), True)
    key = "hydra.sweep.dir" if multirun else "hydra.run.dir"
    try:
        where = Path(str(OmegaConf.select(cfg, key, throw_on_missing=True))).absolute()
    except OmegaConfBaseException:  # resolved by Hydra at run time only: the job checks
        return
    _check_writable(where, key)
    plain, settings = _settings(compose(list(first), False))
    check_outside_cache(where, settings.cache.dir, key)
    if not multirun:
        earlier = inspect_run_dir(where, (*PLANNED_NAMES, *HYDRA_FILES))  # Hydra's too
        verdict(where, earlier, plain, settings, resume=False)
        return
    subdir = OmegaConf.to_container(cfg.hydra.sweep, resolve=False).get("subdir")  # type: ignore[union-attr]
    sweeper = OmegaConf.select(cfg, "hydra.runtime.choices", default={}).get("hydra/sweeper")
    if not where.is_dir() or subdir != _DEFAULT_SUBDIR or sweeper != "basic":
        return
    _check_resumed_sweep(compose, where, [*sweep_params, *overrides])


def _settings(cfg: DictConfig) -> tuple[dict[str, object], RunSettings]:
    """A composition (without Hydra's own config) as the plain mapping ``config.yaml`` holds,
    and its typed settings (an option is never read from it by name)."""
    from omegaconf import OmegaConf

    plain = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    if not isinstance(plain, dict):  # a composed config is a mapping
        raise ConfigError("", "the composed configuration is not a mapping")
    config = {str(k): v for k, v in plain.items()}
    return config, run_settings(config)


#: The longest name of one file or folder most file systems accept (bytes).
NAME_MAX = 255


def _check_writable(path: Path, option: str) -> None:
    """Refuse a location with a name too long, a link to nowhere, or whose nearest existing
    folder cannot be written."""
    for part in path.parts:
        if len(os.fsencode(part)) > NAME_MAX:
            raise ConfigError(option, f"the name {part[:40]}... is longer than {NAME_MAX} "
                              "bytes, more than file systems accept")
    target = path
    while not target.exists() and target != target.parent:
        if target.is_symlink():
            raise ConfigError(option, f"{target} is a link to {os.readlink(target)}, which "
                              "does not exist; remove the link or choose another directory")
        target = target.parent
    if not target.is_dir():
        raise ConfigError(option, f"{target} is not a directory")
    reason = unwritable_reason(target)
    if reason is not None:
        raise ConfigError(option, f"{target} cannot be written ({reason}); choose another "
                                  "output directory")


def sweep_jobs(overrides: Sequence[Override]) -> list[list[str]]:
    """The overrides of every job of a sweep, numbered as Hydra's basic sweeper numbers its
    job directories: a later override of a key replaces an earlier one (a command-line
    value replaces a preset's axis), and the jobs are the product of the keys' values in
    the order the keys first appear."""
    axes: dict[str, list[str]] = {}
    for override in overrides:
        key = override.get_key_element()
        if override.is_sweep_override():
            if not override.is_discrete_sweep():
                raise ConfigError(key, "only comma-separated (choice) sweeps can be resumed")
            axes[key] = [f"{key}={value}" for value in override.sweep_string_iterator()]
        else:
            axes[key] = [f"{key}={override.get_value_element_as_str()}"]
    return [list(job) for job in itertools.product(*axes.values())]


def _check_resumed_sweep(compose: Compose, sweep_dir: Path, arguments: list[str]) -> None:
    """Apply the lifecycle's verdict to every job directory of the sweep that exists."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(
        [a for a in arguments if not a.lstrip("+~").startswith("hydra")])
    jobs = sweep_jobs(parsed)
    existing = sorted(int(p.name) for p in sweep_dir.iterdir() if p.name.isdigit())
    for num in existing:
        if num >= len(jobs):
            continue
        job_dir = sweep_dir / str(num)
        earlier = inspect_run_dir(job_dir, PLANNED_NAMES)
        if earlier.marker is None and not earlier.in_the_way and earlier.live_pid is None:
            continue
        plain, settings = _settings(compose(list(jobs[num]), False))
        verdict(job_dir, earlier, plain, settings, resume=True)

"""The Hydra application behind ``python -m nlosfw``.

Before Hydra takes over, the run's schema and every plugin's config go into Hydra's
ConfigStore and ``+group=name`` is normalised (:mod:`nlosfw.compose.store`). Hydra parses
its own command line; nlosfw reads none of its flags. The checks of everything a command
will run (:func:`nlosfw.compose.preflight`: every swept composition, the plugins, the
files, the memory, the output directories) run in :class:`PreflightCallback`, a Hydra
callback called after Hydra has composed the configuration and before it writes
anything (``on_run_start``, ``on_multirun_start``); ``--cfg``, ``--info`` and ``--help``
run no job and no check.

A command builds one plugin host (:func:`main`) and hands it down: to Hydra's callback
and to the jobs it runs in this process (:data:`_COMMAND`, set for the command's
duration), and to whatever needs the registry within (:func:`nlosfw.plugins.hosting`). A
single run is composed once, by Hydra: the callback makes the run's plan from Hydra's
configuration (the check) and the job runs that plan, its capture file read once. A
worker process of a parallel sweep builds its own host once (:func:`_worker_host`), and
each job of a sweep makes its own plan. Hydra runs with ``HYDRA_FULL_ERROR`` so that its own errors
(an unknown group option, a wrong type) reach :func:`main` as exceptions, which end as
one line naming the option (exit status 2), as every other mistake does.
"""

from __future__ import annotations

import functools
import logging
import os
import sys
import traceback
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hydra.experimental.callback import Callback

from nlosfw.cli import outcomes, workers
from nlosfw.cli.errors import report_job_failure, report_user_error, unexpected_error
from nlosfw.cli.flags import refuse_flags
from nlosfw.cli.reporter import ConsoleReporter
from nlosfw.common.errors import ConfigError, NlosfwError, one_line
from nlosfw.common.files import output_error
from nlosfw.common.logs import FILE_ONLY
from nlosfw.common.resources import config_dir
from nlosfw.compose import (
    composition_error,
    ensure_resolvers,
    normalise_overrides,
    preflight,
    register_configs,
)
from nlosfw.compose.checks import task_config
from nlosfw.pipeline import Pipeline, RunPlan, make_plan
from nlosfw.plugins import PluginHost, hosting

if TYPE_CHECKING:
    from omegaconf import DictConfig

log = logging.getLogger(__name__)


@dataclass(eq=False)
class _Command:
    """One command's plugin host, and the plan of its single run once the check has made
    it (taken by the job)."""

    host: PluginHost
    plan: RunPlan | None = None


#: The command running in this process (set by :func:`main` for its duration; None in a
#: worker process of a parallel sweep).
_COMMAND: ContextVar[_Command | None] = ContextVar("nlosfw_command", default=None)


@functools.cache
def _worker_host() -> PluginHost:
    """The plugin host of a worker process of a parallel sweep: built once per process."""
    from nlosfw.plugins import load_plugins

    return load_plugins()


def _command() -> _Command:
    """The command running here, or a worker process's (a host of its own)."""
    command = _COMMAND.get()
    return _Command(_worker_host()) if command is None else command


def main(argv: Sequence[str]) -> int:
    """Run the Hydra app with ``argv`` (without the program name); return the exit status."""
    import hydra
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    refuse_flags(argv)  # before Hydra's parser sees them, in any spelling it accepts
    argv = normalise_overrides(argv)
    check_override_shapes(argv)
    from nlosfw.plugins import load_plugins  # looked up here: tests substitute it

    host = load_plugins()
    register_configs(host)
    ensure_resolvers()
    decorated = hydra.main(config_path=str(config_dir()), config_name="config",
                           version_base="1.3")(_task)
    token = _COMMAND.set(_Command(host))
    try:
        with _hydra_argv(argv), _hydra_full_error(), hosting(host), \
                workers.forwarding() as sweep:
            decorated()
            outcomes.check(sweep)     # a sweep whose jobs failed: one line naming them
    except (HydraException, OmegaConfBaseException) as err:
        raise composition_error(err, host) from None
    except ValueError as err:  # Hydra refusing its own command line (before any job)
        if _raised_in_a_job(err):
            raise
        raise ConfigError("", f"command line: {one_line(err, whole=True)}") from None
    except OSError as err:  # Hydra's own writes (.hydra/, run.log): a full disk, a bad name
        if _raised_in_a_job(err):
            raise
        where = Path(str(err.filename or "hydra.run.dir"))
        option = "hydra.sweep.dir" if _multirun(argv) else "hydra.run.dir"
        raise (output_error(err, option, where) or ConfigError(
            option, f"{where}: {err.strerror or one_line(err)}")) from None
    except RecursionError:  # Hydra's parser on a deeply nested value
        raise ConfigError("", "command line: an override is nested too deeply") from None
    finally:
        _COMMAND.reset(token)
    return 0


#: The deepest nesting of brackets and the most dotted parts an override may have.
MAX_OVERRIDE_DEPTH = 32
MAX_KEY_PARTS = 32


def check_override_shapes(argv: Sequence[str]) -> None:
    """Refuse (one line) an override nested deeper than :data:`MAX_OVERRIDE_DEPTH` or with
    a key of more than :data:`MAX_KEY_PARTS` parts: Hydra's parser would recurse past
    Python's limit, or look the key up as a file name too long for the system."""
    for arg in argv:
        if arg.startswith("-") or "=" not in arg:
            continue
        key, value = arg.split("=", 1)
        if key.count(".") >= MAX_KEY_PARTS:
            raise ConfigError("", f"command line: the key {key[:40]}... has more than "
                                  f"{MAX_KEY_PARTS} dotted parts")
        depth = deepest = 0
        for char in value:
            depth += (char in "[{(") - (char in "]})")
            deepest = max(deepest, depth)
        if deepest > MAX_OVERRIDE_DEPTH:
            raise ConfigError(key.lstrip("+~"), f"its value is nested {deepest} levels deep; "
                              f"at most {MAX_OVERRIDE_DEPTH} are allowed")


def _multirun(argv: Sequence[str]) -> bool:
    """Whether ``argv`` runs a sweep (``-m``, ``--multirun``, ``hydra.mode=MULTIRUN``)."""
    return any(a in ("-m", "--multirun") or a.replace(" ", "") == "hydra.mode=MULTIRUN"
               for a in argv)


def _raised_in_a_job(err: BaseException) -> bool:
    """Whether ``err`` came from a job (:func:`_task`), not from Hydra itself."""
    return any(frame.f_code is _task.__code__
               for frame, _ in traceback.walk_tb(err.__traceback__))


class PreflightCallback(Callback):
    """The Hydra callback (``hydra.callbacks.nlosfw_preflight`` in config.yaml) that checks
    every configuration a command will run before Hydra writes anything.

    A mistake is reported in one line and ends the command with ``SystemExit`` (exit
    status 2), and so does a check that fails for any other reason: Hydra turns a
    callback's exceptions into warnings and goes on, but lets ``SystemExit`` through.
    """

    def on_run_start(self, config: DictConfig, **kwargs: object) -> None:
        _check(config, multirun=False)

    def on_multirun_start(self, config: DictConfig, **kwargs: object) -> None:
        _check(config, multirun=True)


def _check(config: DictConfig, multirun: bool) -> None:
    """Every check of :func:`~nlosfw.compose.preflight`; any failure ends the command with
    one line and ``SystemExit`` (Hydra would turn an exception into a warning and start the
    run): a mistake with its exit status, a check that could not decide (an exception that
    is not an NlosfwError: a bug, in nlosfw or a plugin) with 2, nothing written. A single
    run's configuration is Hydra's, not composed again, and its plan is kept for the job."""
    from omegaconf import OmegaConf

    command = _command()
    try:
        given = config.hydra.overrides
        hydra = [str(o) for o in OmegaConf.to_container(given.hydra, resolve=False) or []]
        task = [str(o) for o in OmegaConf.to_container(given.task, resolve=False) or []]
        # the user's hydra.* overrides (hydra.run.dir, ...) and the task's, as on the command
        # line; hydra.mode is Hydra's own record of -m
        overrides = [o for o in hydra if not o.startswith("hydra.mode=")] + task
        config_name = str(config.hydra.job.config_name or "config")
        command.plan = preflight(overrides, command.host, config_name, multirun,
                                 composed_run=None if multirun else config)
    except NlosfwError as err:
        report_user_error(err)
        raise SystemExit(err.exit_status) from None
    except Exception as err:  # Hydra would warn and start the run: stop here instead
        failure = NlosfwError(f"the checks before the run failed: {type(err).__name__}: "
                              f"{one_line(err, whole=True)} (a bug in nlosfw or a plugin; "
                              "nothing was written; the traceback with --debug)")
        failure.__traceback__ = err.__traceback__
        report_user_error(failure)
        raise SystemExit(failure.exit_status) from None


def _task(cfg: DictConfig) -> float | None:
    """One Hydra job: the whole pipeline in its run directory, drawn on the console (in a
    worker of a parallel sweep, ended with its status when the sweep is interrupted:
    :mod:`nlosfw.cli.workers`). A failed run ends the command (``SystemExit``); a failed
    job of a sweep ends alone and the sweep goes on (:mod:`nlosfw.cli.outcomes`)."""
    with workers.job():
        return _job(cfg)


def _job(cfg: DictConfig) -> float | None:
    command = _command()
    with hosting(command.host):
        return _run_job(cfg, command)


def _job_plan(cfg: DictConfig, command: _Command) -> RunPlan:
    """The job's plan: the one the check made of this very configuration (a single run),
    else made now (a job of a sweep)."""
    config = task_config(cfg)
    plan, command.plan = command.plan, None
    if plan is not None and plan.config == config:
        return plan
    return make_plan(config, command.host)


def _run_job(cfg: DictConfig, command: _Command) -> float | None:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    logging.captureWarnings(True)  # library warnings go to run.log, not the console
    hydra = HydraConfig.get()
    job = None
    if hydra.mode == RunMode.MULTIRUN:
        job = outcomes.Outcome(num=int(hydra.job.num),
                               overrides=tuple(str(o) for o in hydra.overrides.task))
    pipeline: Pipeline | None = None
    host = command.host
    reporter: ConsoleReporter | None = None
    try:
        plan = _job_plan(cfg, command)
        reporter = ConsoleReporter(host, plan)
        host.manager.register(reporter)
        pipeline = Pipeline(plan, Path(hydra.runtime.output_dir), host,
                            resume=job is not None)
        objective = pipeline.run()
    except NlosfwError as err:
        _failed(err, err.exit_status, job)
        return None
    except MemoryError as err:  # the estimate let it through: still one line
        _failed(NlosfwError(f"out of memory ({one_line(err)}); make the run smaller (the "
                            "sizes, or fewer sweep jobs at once)"), 1, job)
        return None
    except Exception as err:  # any other failure: one line, the traceback in run.log
        log.error("the run failed:", exc_info=err, extra=FILE_ONLY)
        stage = None if pipeline is None else pipeline.stage_reached
        _failed(unexpected_error(err, stage), 1, job)
        return None
    finally:
        if reporter is not None:
            host.manager.unregister(reporter)
    folder = outcomes.sweep_folder()
    if job is not None and folder is not None:
        outcomes.record(folder, job)
    return objective


def _failed(err: BaseException, status: int, job: outcomes.Outcome | None) -> None:
    """End a failed run: its one line, then ``SystemExit(status)``; in a sweep (``job``)
    the job's line and its outcome recorded for the sweep, which goes on (an ordinary
    exception when it cannot be recorded: Hydra's launcher then records the failure)."""
    if job is None:
        report_user_error(err)
        raise SystemExit(status)
    report_job_failure(err, job.num)
    message = one_line(err, whole=True)
    folder = outcomes.sweep_folder()
    failed = outcomes.Outcome(num=job.num, overrides=job.overrides, message=message,
                              exit_status=status)
    if folder is None or not outcomes.record(folder, failed):
        failure = NlosfwError(f"job {job.num} of the sweep failed: {message}")
        failure.exit_status = status
        raise failure


@contextmanager
def _hydra_argv(argv: Sequence[str]) -> Iterator[None]:
    """``sys.argv`` as Hydra reads it: the program name and ``argv``."""
    saved = sys.argv
    sys.argv = [saved[0] if saved else "nlosfw", *argv]
    try:
        yield
    finally:
        sys.argv = saved


@contextmanager
def _hydra_full_error() -> Iterator[None]:
    """Hydra re-raises its errors instead of printing them and exiting with status 1."""
    saved = os.environ.get("HYDRA_FULL_ERROR")
    os.environ["HYDRA_FULL_ERROR"] = "1"
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = saved

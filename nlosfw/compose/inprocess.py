"""Runs from Python (:func:`nlosfw.run`): the command line's configuration and pipeline.

The overrides are the command line's; the configuration is composed and checked as the
command line checks it (:func:`compose_run_config`) before anything is written, and the
same :class:`~nlosfw.pipeline.Pipeline` runs it. What differs: errors are raised as
exceptions (:class:`~nlosfw.common.errors.ConfigError`, ...) instead of ending the
process, the run directory is one the caller names (or a new temporary one), nothing is
drawn on the console, and the stages' results come back in memory.
"""

from __future__ import annotations

import logging
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from nlosfw.common import yaml_safe
from nlosfw.common.errors import ConfigError, one_line
from nlosfw.common.files import write_text
from nlosfw.common.logs import VisibleFormatter
from nlosfw.compose.checks import composition_error, preflight
from nlosfw.compose.store import (
    ensure_resolvers,
    hydra_session,
    normalise_overrides,
    register_configs,
)
from nlosfw.pipeline import Pipeline, PlainConfig, RunOutput, RunPlan
from nlosfw.plugins import PluginHost, hosting, load_plugins

log = logging.getLogger(__name__)


def run_in_process(overrides: Sequence[str], output_dir: str | Path | None = None,
                   config_name: str = "config") -> RunOutput:
    """Compose, check and run one configuration; see :func:`nlosfw.run`."""
    if isinstance(overrides, str):
        raise ConfigError("overrides", f"expected a list of overrides, got the string "
                          f"{overrides!r} (write [{overrides!r}])")
    overrides = [str(o) for o in overrides]
    host = load_plugins()
    with hosting(host):
        plan = plan_run(overrides, host, config_name)
        run_dir = _new_run_dir(output_dir)
        write_text(run_dir / ".hydra" / "overrides.yaml", yaml_safe.dump(overrides))
        pipeline = Pipeline(plan, run_dir, host)
        with _run_log(run_dir / "run.log"):
            pipeline.run()
    return RunOutput(dir=run_dir, config=plan.config, metrics=pipeline.metrics,
                     stages=pipeline.stage_results)


def compose_run_config(overrides: Sequence[str], host: PluginHost,
                       config_name: str = "config") -> PlainConfig:
    """The resolved configuration of one run, checked as the command line checks it.

    ``overrides`` are the command line's (``+group=name`` included); a sweep, a flag or
    a ``hydra.*`` setting is refused with a one-line :class:`ConfigError`.
    """
    return plan_run(overrides, host, config_name).config


def plan_run(overrides: Sequence[str], host: PluginHost,
             config_name: str = "config") -> RunPlan:
    """The plan of one run (:func:`~nlosfw.pipeline.make_plan`), its configuration composed
    once and checked as the command line checks it (the output directories too); the
    overrides as for :func:`compose_run_config`."""
    from hydra import compose
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
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
    with hydra_session():  # one thread at a time: Hydra's state is the process's
        register_configs(host)
        ensure_resolvers()
        try:
            cfg = compose(config_name=config_name, overrides=list(overrides),
                          return_hydra_config=True)
        except (HydraException, OmegaConfBaseException) as err:
            raise composition_error(err, host) from None
        plan = preflight(overrides, host, config_name, composed_run=cfg)
    if plan is None:  # a single run's preflight returns its plan
        raise ConfigError("overrides", "no run to plan")
    return plan


def _new_run_dir(output_dir: str | Path | None) -> Path:
    """``output_dir`` (created; it must be new or empty), or a new temporary directory."""
    if output_dir is None:
        path = Path(tempfile.mkdtemp(prefix="nlosfw-run-"))
        log.info("run directory: %s", path)
        return path
    path = Path(output_dir).expanduser()
    if path.exists() and not path.is_dir():
        raise ConfigError("output_dir", f"{path} is a file; give a new or empty directory")
    if path.is_dir() and any(path.iterdir()):
        raise ConfigError("output_dir", f"{path} already holds files; give a new or empty "
                          "directory (nothing is written over an earlier run)")
    path.mkdir(parents=True, exist_ok=True)
    return path.resolve()


@contextmanager
def _run_log(path: Path) -> Iterator[None]:
    """nlosfw's log records at INFO and above into the run's ``run.log`` while it runs; only
    warnings and errors reach the caller's handlers (a notebook's), not every INFO line.

    Runs in several threads at once share one routing (counted under a lock), so the logger's
    own settings come back when the last run ends, whatever order they end in; each run.log
    keeps its own thread's records and its workers', not another run's."""
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(VisibleFormatter())
    me = threading.get_ident()
    with _ROUTING_LOCK:
        routing = _Routing.enter(logging.getLogger("nlosfw"), me)
    handler.addFilter(lambda record: routing.belongs_to(record, me))
    routing.logger.addHandler(handler)
    try:
        yield
    finally:
        routing.logger.removeHandler(handler)
        handler.close()
        with _ROUTING_LOCK:
            routing.leave(me)


_ROUTING_LOCK = threading.Lock()  # guards _Routing.enter/leave; holds no data itself


class _Routing(logging.Handler):
    """Installed on the ``nlosfw`` logger while at least one run is in progress: stops
    propagation and hands records at WARNING and above to the parent loggers' handlers (as
    propagation would), or to logging's last resort when they have none. It remembers the
    logger's level and propagation from before the first run and restores them after the
    last one."""

    def __init__(self, logger: logging.Logger) -> None:
        super().__init__(logging.WARNING)
        self.logger = logger
        self.saved_level, self.saved_propagate = logger.level, logger.propagate
        self.run_threads: set[int] = set()

    @classmethod
    def enter(cls, logger: logging.Logger, thread: int) -> _Routing:
        """The routing in place on ``logger`` (installed if none is), with ``thread`` added."""
        routing = next((h for h in logger.handlers if isinstance(h, cls)), None)
        if routing is None:
            routing = cls(logger)
            logger.addHandler(routing)
            if routing.saved_propagate:
                logger.propagate = False
            else:  # the caller already keeps nlosfw's records to itself: forward nothing
                routing.setLevel(logging.CRITICAL + 1)
            if logger.getEffectiveLevel() > logging.INFO:
                logger.setLevel(logging.INFO)
        routing.run_threads.add(thread)
        return routing

    def leave(self, thread: int) -> None:
        """``thread``'s run has ended; after the last one the logger is as it was."""
        self.run_threads.discard(thread)
        if not self.run_threads:
            self.logger.removeHandler(self)
            self.logger.setLevel(self.saved_level)
            self.logger.propagate = self.saved_propagate

    def belongs_to(self, record: logging.LogRecord, thread: int) -> bool:
        """Whether ``record`` goes to the run.log of the run in ``thread``: its own records
        and those of threads that run no other run (its workers)."""
        return record.thread == thread or record.thread not in self.run_threads

    def handle(self, record: logging.LogRecord) -> bool:
        if record.levelno < self.level:
            return False
        parent = self.logger.parent
        if parent is not None and parent.hasHandlers():
            parent.handle(record)
        elif logging.lastResort is not None and record.levelno >= logging.lastResort.level:
            logging.lastResort.handle(record)
        return True

    def emit(self, record: logging.LogRecord) -> None:  # handle() does the work
        pass

"""Runs from Python (:func:`nlosfw.run`): the command line's pipeline, returning its results.

The overrides are the command line's; the configuration is composed and checked by the
same Hydra app (:func:`~nlosfw.app.hydra_app.compose_run_config`) before anything is
written, and the same :class:`~nlosfw.app.pipeline.Pipeline` runs it. What differs: errors
are raised as exceptions (:class:`~nlosfw.common.errors.ConfigError`, ...) instead of
ending the process, the run directory is one the caller names (or a new temporary one),
and the stages' results come back in memory.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from nlosfw.app.hydra_app import compose_run_config
from nlosfw.app.pipeline import Pipeline
from nlosfw.app.results import RunOutput
from nlosfw.common import yaml_safe
from nlosfw.common.errors import ConfigError
from nlosfw.common.files import write_text
from nlosfw.plugins import load_plugins

log = logging.getLogger(__name__)


def run_in_process(overrides: Sequence[str], output_dir: str | Path | None = None,
                   config_name: str = "config") -> RunOutput:
    """Compose, check and run one configuration; see :func:`nlosfw.run`."""
    if isinstance(overrides, str):
        raise ConfigError("overrides", f"expected a list of overrides, got the string "
                          f"{overrides!r} (write [{overrides!r}])")
    overrides = [str(o) for o in overrides]
    host = load_plugins()
    config = compose_run_config(overrides, host, config_name)
    run_dir = _new_run_dir(output_dir)
    write_text(run_dir / ".hydra" / "overrides.yaml", yaml_safe.dump(overrides))
    pipeline = Pipeline(run_dir, config, host)
    with _run_log(run_dir / "run.log"):
        pipeline.run()
    return RunOutput(dir=run_dir, config=config, metrics=pipeline.metrics,
                     stages=pipeline.stage_results)


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
    """nlosfw's log records at INFO and above into the run's ``run.log`` while it runs."""
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("[%(asctime)s][%(name)s][%(levelname)s] %(message)s"))
    logger = logging.getLogger("nlosfw")
    level = logger.level
    logger.addHandler(handler)
    if logger.getEffectiveLevel() > logging.INFO:
        logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        handler.close()

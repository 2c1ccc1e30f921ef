"""One run's directory: artefacts under fixed names, stage timings, metrics, lifecycle hooks.

Artefact names (relative to the run directory; see the README):

========================  ================================================
``config.yaml``           the resolved configuration of the run
``run.log``               the log
``metrics.json``          metrics, nested by stage (:mod:`nlosfw.app.metrics`)
``metrics.schema.json``   the JSON Schema of metrics.json
``capture.hdf5``          the transient, in y-tal's HDF5 layout
``phasor_field.hdf5``     the full phasor field of the capture
``field_model.npz``       the trained field model (its plugin's format)
``fields/<source>.hdf5``  the fields imaged: true, raw, model, interp
``reconstructions/<source>.hdf5``  their reconstructions
``figures/*.png``         figures
``report.html``           all of it in one self-contained page
========================  ================================================

The large files (capture, phasor field, fields, model, reconstructions) are written only
when ``output.keep`` lists them (:class:`~nlosfw.app.settings.Artefact`). Every file is
claimed in the directory's run marker before it is written (:mod:`nlosfw.app.lifecycle`),
so a later run knows exactly which files are this run's.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from nlosfw.app.console import FILE_ONLY
from nlosfw.app.lifecycle import RunHold
from nlosfw.app.metrics import RunError, RunInfo, RunMetrics, Status, metrics_schema_text
from nlosfw.app.settings import Artefact
from nlosfw.common.errors import DataError
from nlosfw.common.files import atomic_path, write_text
from nlosfw.plugins import PluginHost

log = logging.getLogger(__name__)

ARTEFACTS = {
    "config": "config.yaml",
    "metrics": "metrics.json",
    "metrics_schema": "metrics.schema.json",
    "capture": "capture.hdf5",
    "phasor_field": "phasor_field.hdf5",
    "field_model": "field_model.npz",
}
#: Top-level names a run may create in its directory (Hydra adds .hydra and run.log).
PLANNED_NAMES = (*ARTEFACTS.values(), "fields", "reconstructions", "figures",
                 "thesis_comparison.md", "report.html")


class RunContext:
    """Writes a run's artefacts atomically (never over existing files) and holds its metrics.

    ``metrics`` is the run's :class:`RunMetrics` so far; stages replace its sections as
    they finish, and :meth:`finish` writes it. ``keep`` lists the large artefacts to write
    (``None``: all of them). With a ``hold`` on the directory every file is claimed in its
    run marker before it is written.
    """

    def __init__(self, run_dir: Path, host: PluginHost, info: RunInfo,
                 keep: frozenset[Artefact] | None = None) -> None:
        self.run_dir = Path(run_dir)
        self.host = host
        self.metrics = RunMetrics(run=info)
        self.started = time.perf_counter()
        self.keep = frozenset(Artefact) if keep is None else keep
        self.hold: RunHold | None = None
        self.stage_reached: str | None = None
        """The stage running now, or the last one started."""

    def path(self, name: str) -> Path:
        """Absolute path of an artefact given by key (``capture``) or relative name."""
        return self.run_dir / ARTEFACTS.get(name, name)

    def write(self, name: str, writer: Callable[[Path], Any], kind: str | None = None,
              keep_as: Artefact | None = None) -> Path | None:
        """Create artefact ``name`` with ``writer(tmp_path)``, publish it atomically, notify.

        An artefact of category ``keep_as`` that ``keep`` leaves out is not written (None).
        """
        if keep_as is not None and keep_as not in self.keep:
            log.debug("%s not written: output.keep does not list %s", name, keep_as)
            return None
        final = self.path(name)
        self._claim(final)
        with atomic_path(final) as tmp:
            writer(tmp)
        self.host.hook.on_artefact_written(path=str(final), kind=kind or name)
        return final

    def write_text(self, name: str, text: str, kind: str | None = None) -> Path:
        self._claim(self.path(name))
        final = write_text(self.path(name), text)
        self.host.hook.on_artefact_written(path=str(final), kind=kind or name)
        return final

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time a pipeline stage into ``metrics.timings.<name>`` and fire ``on_stage_end``."""
        start = time.perf_counter()
        self.stage_reached = name
        log.info("stage %s: started", name, extra=FILE_ONLY)
        yield
        seconds = time.perf_counter() - start
        self._record_time(name, seconds)
        log.info("stage %s: %.2f s", name, seconds, extra=FILE_ONLY)
        self.host.hook.on_stage_end(stage=name, seconds=seconds)

    def finish(self, status: Status, error: RunError | None = None) -> Path:
        """Write ``metrics.json`` with the final status (and, for a failed or interrupted
        run, where and why it ended) and total time, and its JSON Schema
        ``metrics.schema.json`` beside it."""
        self._record_time("total", time.perf_counter() - self.started)
        self.metrics = dataclasses.replace(self.metrics, status=status, error=error)
        path = self.path("metrics")
        if path.exists():
            raise DataError(f"{path}: already exists; refusing to overwrite it")
        text = self.metrics.dumps()
        if not self.path("metrics_schema").exists():  # a failed finish may have written it
            self.write_text("metrics_schema", metrics_schema_text())
        return self.write_text("metrics", text)

    def size(self) -> int:
        """Bytes in the run directory (every file, Hydra's and the log included)."""
        return sum(p.stat().st_size for p in self.run_dir.rglob("*") if p.is_file())

    def _claim(self, path: Path) -> None:
        if self.hold is not None:
            self.hold.claim(path.relative_to(self.run_dir).as_posix())

    def _record_time(self, name: str, seconds: float) -> None:
        timings = dataclasses.replace(self.metrics.timings, **{name: round(seconds, 4)})
        self.metrics = dataclasses.replace(self.metrics, timings=timings)


def format_size(size: int) -> str:
    """Bytes as ``512 B``, ``7.2 MB`` (decimal units, as ``ls -h --si`` and file browsers)."""
    if size < 1000:
        return f"{size} B"
    value = size / 1000
    for unit in ("kB", "MB"):
        if value < 1000:
            return f"{value:.1f} {unit}"
        value /= 1000
    return f"{value:.1f} GB"

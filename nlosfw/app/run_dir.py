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
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from nlosfw.app.metrics import RunInfo, RunMetrics, Status, metrics_schema_text
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


class RunContext:
    """Writes a run's artefacts atomically (never over existing files) and holds its metrics.

    ``metrics`` is the run's :class:`RunMetrics` so far; stages replace its sections as
    they finish, and :meth:`finish` writes it.
    """

    def __init__(self, run_dir: Path, host: PluginHost, info: RunInfo) -> None:
        self.run_dir = Path(run_dir)
        self.host = host
        self.metrics = RunMetrics(run=info)
        self.started = time.perf_counter()

    def path(self, name: str) -> Path:
        """Absolute path of an artefact given by key (``capture``) or relative name."""
        return self.run_dir / ARTEFACTS.get(name, name)

    def write(self, name: str, writer: Callable[[Path], Any], kind: str | None = None) -> Path:
        """Create artefact ``name`` with ``writer(tmp_path)``, publish it atomically, notify."""
        final = self.path(name)
        with atomic_path(final) as tmp:
            writer(tmp)
        self.host.hook.on_artefact_written(path=str(final), kind=kind or name)
        return final

    def write_text(self, name: str, text: str, kind: str | None = None) -> Path:
        final = write_text(self.path(name), text)
        self.host.hook.on_artefact_written(path=str(final), kind=kind or name)
        return final

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time a pipeline stage into ``metrics.timings.<name>`` and fire ``on_stage_end``."""
        start = time.perf_counter()
        log.info("stage %s: started", name)
        yield
        seconds = time.perf_counter() - start
        self._record_time(name, seconds)
        log.info("stage %s: %.2f s", name, seconds)
        self.host.hook.on_stage_end(stage=name, seconds=seconds)

    def finish(self, status: Status) -> Path:
        """Write ``metrics.json`` with the final status and total time, and its JSON Schema
        ``metrics.schema.json`` beside it."""
        self._record_time("total", time.perf_counter() - self.started)
        self.metrics = dataclasses.replace(self.metrics, status=status)
        path = self.path("metrics")
        if path.exists():
            raise DataError(f"{path}: already exists; refusing to overwrite it")
        text = self.metrics.dumps()
        if not self.path("metrics_schema").exists():  # a failed finish may have written it
            self.write_text("metrics_schema", metrics_schema_text())
        return self.write_text("metrics", text)

    def _record_time(self, name: str, seconds: float) -> None:
        timings = dataclasses.replace(self.metrics.timings, **{name: round(seconds, 4)})
        self.metrics = dataclasses.replace(self.metrics, timings=timings)

"""One run's directory: artefacts under fixed names, stage timings, metrics, lifecycle hooks.

Artefact names (relative to the run directory; see the README):

========================  ================================================
``config.yaml``           the resolved configuration of the run
``run.log``               the log
``metrics.json``          metrics, nested by stage (schema in the README)
``capture.hdf5``          the transient, in y-tal's HDF5 layout
``phasor_field.hdf5``     the full phasor field of the capture
``field_model.npz``       the trained field model (its plugin's format)
``fields/<source>.hdf5``  the fields imaged: true, raw, model, interp
``reconstructions/<source>.hdf5``  their reconstructions
``figures/*.png``         figures
========================  ================================================
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from nlosfw.common.errors import DataError
from nlosfw.common.files import atomic_path, write_text
from nlosfw.plugins import PluginHost

log = logging.getLogger(__name__)

METRICS_SCHEMA_VERSION = 1

ARTEFACTS = {
    "config": "config.yaml",
    "metrics": "metrics.json",
    "capture": "capture.hdf5",
    "phasor_field": "phasor_field.hdf5",
    "field_model": "field_model.npz",
}


class RunContext:
    """Writes a run's artefacts atomically (never over existing files) and records metrics."""

    def __init__(self, run_dir: Path, host: PluginHost) -> None:
        self.run_dir = Path(run_dir)
        self.host = host
        self.metrics: dict[str, Any] = {"schema_version": METRICS_SCHEMA_VERSION,
                                        "status": "running", "timings": {}}
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
        """Time a pipeline stage into ``metrics['timings'][name]`` and fire ``on_stage_end``."""
        start = time.perf_counter()
        log.info("stage %s: started", name)
        yield
        seconds = time.perf_counter() - start
        self.metrics["timings"][name] = round(seconds, 4)
        log.info("stage %s: %.2f s", name, seconds)
        self.host.hook.on_stage_end(stage=name, seconds=seconds)

    def finish(self, status: str) -> Path:
        """Write ``metrics.json`` with the final status and total time."""
        self.metrics["status"] = status
        self.metrics["timings"]["total"] = round(time.perf_counter() - self.started, 4)
        text = json.dumps(_json_safe(self.metrics), indent=2, sort_keys=False) + "\n"
        path = self.path("metrics")
        if path.exists():
            raise DataError(f"{path}: already exists; refusing to overwrite it")
        return self.write_text("metrics", text)


def _json_safe(value: Any) -> Any:
    """NaN and infinities become null (JSON has none); numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        try:
            value = value.item()
        except (TypeError, ValueError):
            return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value

"""One run's files: fixed names, each claimed in the run's marker, then written atomically.

Names (relative to the run directory; see docs/guide/outputs.md):

========================  ================================================
``config.yaml``           the resolved configuration of the run
``run.log``               the log
``metrics.json``          metrics, nested by stage (:mod:`nlosfw.pipeline.metrics`)
``metrics.schema.json``   the JSON Schema of metrics.json
``capture.hdf5``          the transient, in y-tal's HDF5 layout
``phasor_field.hdf5``     the full phasor field of the capture
``field_model.npz``       the trained field model (its plugin's format)
``fields/<source>.hdf5``  the fields imaged: true, raw, model, interp
``reconstructions/<source>.hdf5``  their reconstructions (``native-bins.hdf5``: the
                          reference picture, :mod:`nlosfw.evaluation.reference`)
``figures/*.png``         figures
``published_numbers.md``  published numbers next to the run's (its ``published`` tables)
``report.html``           all of it in one self-contained page
========================  ================================================

The large files (capture, phasor field, fields, model, reconstructions) are written only
when ``output.keep`` lists them (:class:`~nlosfw.pipeline.settings.Artefact`). Every file
is claimed in the directory's run marker before it is written
(:mod:`nlosfw.pipeline.lifecycle`), so a later run knows exactly which files are this run's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from nlosfw.common.errors import DataError
from nlosfw.common.files import atomic_path, write_text
from nlosfw.pipeline.events import RunEvents
from nlosfw.pipeline.lifecycle import RunHold
from nlosfw.pipeline.metrics import RunMetrics, metrics_schema_text
from nlosfw.pipeline.pause import pause_point
from nlosfw.pipeline.settings import Artefact

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
                 "published_numbers.md", "report.html")

#: Writes one file at the temporary path it is given.
FileWriter = Callable[[Path], object]


class RunFiles:
    """Writes a run's files atomically, never over an existing file.

    ``keep`` lists the large artefacts to write (``None``: all of them). With a ``hold``
    on the directory every file is claimed in its run marker before it is written; every
    file written is reported (``on_artefact_written``).
    """

    def __init__(self, run_dir: Path, events: RunEvents,
                 keep: frozenset[Artefact] | None = None) -> None:
        self.run_dir = Path(run_dir)
        self.events = events
        self.keep = frozenset(Artefact) if keep is None else keep
        self.hold: RunHold | None = None

    def path(self, name: str) -> Path:
        """Absolute path of an artefact given by key (``capture``) or relative name."""
        return self.run_dir / ARTEFACTS.get(name, name)

    def write(self, name: str, writer: FileWriter, kind: str | None = None,
              keep_as: Artefact | None = None) -> Path | None:
        """Create artefact ``name`` with ``writer(tmp_path)``, publish it atomically, report it.

        An artefact of category ``keep_as`` that ``keep`` leaves out is not written (None).
        """
        if keep_as is not None and keep_as not in self.keep:
            log.debug("%s not written: output.keep does not list %s", name, keep_as)
            return None
        final = self.path(name)
        self._claim(final)
        with atomic_path(final) as tmp:
            writer(tmp)
            pause_point(final.relative_to(self.run_dir).as_posix())  # tests only
        self.events.artefact_written(str(final), kind or name)
        return final

    def write_text(self, name: str, text: str, kind: str | None = None,
                   overwrite: bool = False) -> Path:
        """Create the text file ``name`` atomically (``overwrite``: replace this run's own
        file of that name), report it."""
        self._claim(self.path(name))
        final = write_text(self.path(name), text, overwrite=overwrite)
        self.events.artefact_written(str(final), kind or name)
        return final

    def write_metrics(self, metrics: RunMetrics, replace: bool = False) -> Path:
        """``metrics.json``, and its JSON Schema ``metrics.schema.json`` beside it.

        ``replace``: a metrics.json this run wrote already is replaced (a failure after
        it); when that fails too, it is removed, so that it never says how the run did not
        end (without one the run reads as unfinished)."""
        path = self.path("metrics")
        if path.exists() and not replace:
            raise DataError(f"{path}: already exists; refusing to overwrite it")
        text = metrics.dumps()
        if not self.path("metrics_schema").exists():  # a failed finish may have written it
            self.write_text("metrics_schema", metrics_schema_text())
        try:
            return self.write_text("metrics", text, overwrite=replace)
        except BaseException:
            if replace:
                path.unlink(missing_ok=True)
            raise

    def size(self) -> int:
        """Bytes in the run directory (every file, Hydra's and the log included)."""
        return sum(p.stat().st_size for p in self.run_dir.rglob("*") if p.is_file())

    def _claim(self, path: Path) -> None:
        if self.hold is not None:
            self.hold.claim(path.relative_to(self.run_dir).as_posix())

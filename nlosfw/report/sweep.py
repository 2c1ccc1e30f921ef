"""A sweep's report (``python -m nlosfw report DIR``): every run under DIR in one report.

Reads only regular files inside DIR, each bounded (:mod:`nlosfw.report.inputs`), and
writes into a new ``DIR/report/`` (or ``report-2``, ... if that exists: earlier reports
are never overwritten; a report that fails leaves no folder behind):

* ``report.csv``: one row per run (its scene or capture file, sparsity, seed, field
  errors and reconstruction scores);
* ``study.csv``: the runs grouped over seeds (:mod:`nlosfw.report.study`): per condition,
  sparsity and source, the mean, standard deviation, minimum and maximum of each score;
* ``report.png``: reconstruction quality against the swept parameter, one line per
  field model with ``raw`` and ``interp`` on every panel. A sweep over sparsity gets the
  study's figure (PSNR, SSIM, depth RMSE against the undersampling factor, spread over
  seeds, :func:`nlosfw.report.study.study_figure`); any other sweep the quality plot of
  :mod:`nlosfw.report.quality` (SSIM, PSNR and the held-out field error against the swept
  key);
* ``report.md``: the figure's numbers and every run as markdown tables, plus the runs'
  numbers next to published ones when their configs carry ``published`` tables;
* ``report.html``: all of it in one self-contained page, linking each run's own
  ``report.html``.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from pathlib import Path

from nlosfw.common.config import Scalar
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.files import atomic_path, storage_error, unwritable_reason, write_text
from nlosfw.common.text import csv_cell
from nlosfw.common.text import markdown as markdown_text
from nlosfw.pipeline.metrics import (
    ErrorMetrics,
    FieldMetrics,
    ImageScores,
    SplitErrors,
    SplitMetrics,
)
from nlosfw.report.html_report import sweep_report
from nlosfw.report.published_numbers import published_comparison
from nlosfw.report.quality import (
    QualityTable,
    quality_figure,
    quality_points,
    quality_table,
    quality_tables,
    sweep_layout,
)
from nlosfw.report.records import RunRecord, find_runs, read_run
from nlosfw.report.study import SCORES, study_csv_rows, study_figure, study_rows, study_table
from nlosfw.report.tables import format_cell, markdown_table

log = logging.getLogger(__name__)

Column = Callable[[RunRecord], Scalar]


def _field(source: str, get: Callable[[FieldMetrics], Scalar]) -> Column:
    """A column from field model ``source``'s metrics (empty where it was not fitted)."""
    def column(record: RunRecord) -> Scalar:
        entry = record.metrics.field_entry(source)
        return None if entry is None else get(entry)

    return column


def _nmse(source: str, split: Callable[[SplitErrors], ErrorMetrics]) -> Column:
    """The NMSE (dB) of field model ``source`` on one set of the protocol."""
    def nmse(entry: FieldMetrics) -> float | None:
        return None if entry.splits is None else split(entry.splits).nmse_db

    return _field(source, nmse)


def _image(source: str, get: Callable[[ImageScores], Scalar]) -> Column:
    """A column from the reconstruction scores of ``source``."""
    def column(record: RunRecord) -> Scalar:
        scores = record.metrics.image_scores(source)
        return None if scores is None else get(scores)

    return column


def _split(get: Callable[[SplitMetrics], Scalar]) -> Column:
    """A column from the run's split (empty where the run stopped before it)."""
    def column(record: RunRecord) -> Scalar:
        split = record.metrics.split
        return None if split is None else get(split)

    return column


def _noise(record: RunRecord) -> Scalar:
    capture = record.metrics.capture
    return None if capture is None or not capture.noise else capture.noise.get("model")


def _scores(source: str) -> tuple[tuple[str, Column], ...]:
    """The reconstruction scores of ``source``, one column each."""
    return tuple((f"{source}_{name}", _image(source, partial(_attr, name=name)))
                 for name in SCORES)


def _attr(scores: ImageScores, name: str) -> Scalar:
    return getattr(scores, name)


#: Columns of the report, in order: (column name, its value in a run's record).
COLUMNS: tuple[tuple[str, Column], ...] = (
    ("run", lambda r: r.name),
    ("status", lambda r: r.metrics.status),
    ("scene", lambda r: r.metrics.run.scene),
    ("simulator", lambda r: r.metrics.run.simulator),
    ("capture_file", lambda r: r.metrics.run.capture_file),
    ("capture_format", lambda r: r.metrics.run.capture_format),
    ("noise", _noise),
    ("model", lambda r: r.metrics.run.model),
    ("seed", _field("model", lambda e: e.seed)),
    ("imager", lambda r: r.metrics.run.imager),
    ("pattern", _split(lambda s: s.pattern)),
    ("undersampling", _split(lambda s: s.undersampling)),
    ("train_samples", _split(lambda s: s.train_samples)),
    ("overrides", lambda r: " ".join(r.overrides)),
    ("n_parameters", _field("model", lambda e: e.n_parameters)),
    ("parameters_per_value", _field("model", lambda e: e.parameters_per_value)),
    ("fit_seconds", _field("model", lambda e: e.fit.seconds)),
    ("final_loss", _field("model", lambda e: e.fit.final_loss)),
    ("model_heldout_pixels_nmse_db", _nmse("model", lambda s: s.heldout_pixels)),
    ("model_heldout_freqs_nmse_db", _nmse("model", lambda s: s.heldout_frequencies)),
    ("model_all_nmse_db", _nmse("model", lambda s: s.all)),
    ("interp_heldout_pixels_nmse_db", _nmse("interp", lambda s: s.heldout_pixels)),
    ("interp_heldout_freqs_nmse_db", _nmse("interp", lambda s: s.heldout_frequencies)),
    ("interp_all_nmse_db", _nmse("interp", lambda s: s.all)),
    *_scores("model"),
    *_scores("interp"),
    *_scores("raw"),
    ("true_depth_rmse_m", _image("true", lambda s: s.depth_rmse_m)),
    ("total_seconds", lambda r: r.metrics.timings.total),
)


def report_rows(records: Sequence[RunRecord]) -> list[dict[str, str]]:
    """One row of formatted cells per run, by column name."""
    return [{name: format_cell(value(r)) for name, value in COLUMNS} for r in records]


def to_csv(rows: list[dict[str, str]]) -> str:
    return csv_text([c for c, _ in COLUMNS], [[row[c] for c, _ in COLUMNS] for row in rows])


def csv_text(header: Sequence[str], rows: Sequence[Sequence[Scalar]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow([csv_cell(c) for c in header])
    writer.writerows([csv_cell(c) for c in row] for row in rows)
    return buffer.getvalue()


def to_markdown(rows: list[dict[str, str]], columns: Sequence[str] | None = None) -> str:
    columns = list(columns or [c for c, _ in COLUMNS])
    return markdown_table(columns, [[row.get(c, "") for c in columns] for row in rows])


#: The files a report writes into its folder.
REPORT_FILES = ("report.csv", "study.csv", "report.md", "report.png", "report.html")


def _new_report_dir(root: Path) -> Path:
    """A new folder ``root/report`` (``report-2``, ... when the name is taken), made now; a
    one-line error when ``root`` cannot be written (exit status 2), a link to nowhere is in
    the way (2) or the disk is full (1)."""
    reason = unwritable_reason(root)
    if reason is not None:
        raise ConfigError("", f"{root}: a report cannot be written there ({reason})")
    n = 1
    while True:
        target = root / ("report" if n == 1 else f"report-{n}")
        n += 1
        try:
            target.mkdir()
        except FileExistsError:
            if target.is_symlink() and not target.exists():
                raise ConfigError("", f"{target}: a link to {os.readlink(target)}, which does "
                                      "not exist; remove it to write the report there") from None
            continue
        except OSError as err:
            if err.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise ConfigError("", f"{root}: a report cannot be written there "
                                      f"({err.strerror})") from None
            raise (storage_error(target, err) or err) from None
        return target


@contextlib.contextmanager
def _report_dir(root: Path) -> Iterator[Path]:
    """A new report folder under ``root`` (:func:`_new_report_dir`) for the block to write
    into; when the block fails (a full disk, an interruption), what it wrote there and the
    folder are removed: no half-written report is left."""
    out = _new_report_dir(root)
    try:
        yield out
    except BaseException:
        for name in REPORT_FILES:
            with contextlib.suppress(OSError):
                (out / name).unlink()
        with contextlib.suppress(OSError):
            out.rmdir()
        raise


#: What the study table means with count splitting.
_COUNT_SPLITTING_NOTE = (
    "Count splitting: every bin's photon count was split into two independent halves; the "
    "models trained on half A's kept wall points. Held-out excess = error at the wall points "
    "not kept against half B's measured field minus its noise floor (the error of a perfect "
    "predictor), in dB of B's power there: lower is better. `true` is half B's full scan "
    "(the reference) and `ceiling` half A's full scan scored against it.\n\n")


def write_report(root: Path, x: str | None = None) -> tuple[Path, list[dict[str, str]]]:
    """Write report.csv, report.md, report.png and report.html for the runs under ``root``
    into a new
    report directory (returned, with the table's rows); ``x`` is the override key on the
    quality plot's x axis (default: chosen by :func:`nlosfw.report.quality.sweep_layout`)."""
    runs = find_runs(root)
    if not runs:
        raise DataError(f"{root}: holds no run (no metrics.json below it)")
    records = [read_run(r, root) for r in runs]
    rows = report_rows(records)
    layout = sweep_layout(records, x)
    points = quality_points(records, layout)
    study = study_rows(records)
    # a sweep over sparsity is a study: its figure and table aggregate the seeds per
    # condition and sparsity; any other sweep gets the quality plot against its key
    # (a count-splitting study even at one sparsity: its table holds the held-out scores)
    by_sparsity = x is None and (len({(r.pattern, r.undersampling) for r in study}) > 1
                                 or any(r.scores["heldout_excess_db"].n for r in study))
    with _report_dir(root) as out:
        write_text(out / "report.csv", to_csv(rows))
        write_text(out / "study.csv", csv_text(*study_csv_rows(study)))
        markdown = f"# nlosfw report: {markdown_text(str(root))}\n\n{len(rows)} runs.\n\n"
        if by_sparsity:
            header, cells = study_table(study)
            tables = [QualityTable(heading="reconstruction quality against sparsity, mean ± "
                                           "standard deviation over seeds",
                                   header=tuple(header), rows=tuple(tuple(c) for c in cells))]
            markdown += ("## Reconstruction quality against sparsity\n\n"
                         "![reconstruction quality against sparsity](report.png)\n\n"
                         "Scores against the full capture's reconstruction (amplitudes, each "
                         "normalised to its maximum; scikit-image PSNR and SSIM at their "
                         "defaults), mean ± standard deviation over the runs of each row "
                         "(seeds); `true` is the full capture itself.\n\n"
                         + (_COUNT_SPLITTING_NOTE
                            if any(r.scores["heldout_excess_db"].n for r in study) else "")
                         + markdown_table(header, cells) + "\n")
        else:
            tables = quality_tables(points, layout)
            label = markdown_text(layout.x_label)
            markdown += (f"## Quality against {label}\n\n![quality against "
                         f"{label}](report.png)\n\n{quality_table(points, layout)}\n")
        markdown += f"## Every run\n\n{to_markdown(rows)}"
        published = published_comparison(records)
        if published:
            markdown += "\n## Next to published numbers\n\n" + published
        write_text(out / "report.md", markdown)
        with atomic_path(out / "report.png") as tmp:
            if by_sparsity:
                study_figure(study, tmp)
            else:
                quality_figure(points, layout).savefig(tmp, dpi=110, format="png")
        write_text(out / "report.html", sweep_report(root, out, records, rows,
                                                     (out / "report.png").read_bytes(), tables))
    return out, rows

"""The report plugin: the files of a run's report, written by subscribers to the run hooks.

Registered through nlosfw's own entry point (``report`` in the ``nlosfw`` group), like any
third-party plugin: at the report stage of a complete run, the comparison with published
numbers (for a run with ``published`` tables, such as the thesis presets) and the figures
(of a run stopped before it imaged: the capture's time profile); after ``metrics.json``,
the run's ``report.html``.
matplotlib is imported only when a figure is drawn.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from nlosfw.plugins import hookimpl

if TYPE_CHECKING:
    from nlosfw.pipeline import CaptureResult, RunFiles, RunMetrics, RunResults, RunSettings

log = logging.getLogger(__name__)


@hookimpl
def write_run_report(files: RunFiles, results: RunResults, metrics: RunMetrics,
                     settings: RunSettings) -> None:
    """The comparison with published numbers (a run with ``published`` tables) and the
    figures."""
    if settings.published:
        from nlosfw.report.published_numbers import FILE_NAME, published_comparison
        from nlosfw.report.records import RunRecord

        record = RunRecord(name=files.run_dir.name, metrics=metrics,
                           published=settings.published)
        text = published_comparison([record])
        if text:
            files.write_text(FILE_NAME, text, kind="report")
    if settings.figures.enabled and metrics.reconstruction is not None:
        from nlosfw.report.figures import write_figures

        write_figures(files, results, metrics.run, metrics.reconstruction,
                      settings.figures.dpi)


@hookimpl
def write_capture_report(files: RunFiles, capture: CaptureResult,
                         depth_range: tuple[float, float], metrics: RunMetrics,
                         settings: RunSettings) -> None:
    """A run stopped before it imaged: the capture's time profile, ``depth_range`` shaded."""
    if settings.figures.enabled:
        from nlosfw.report.titles import run_title
        from nlosfw.report.views import write_time_profile

        write_time_profile(files, capture.capture, depth_range,
                           run_title(metrics.run, capture), settings.figures.dpi)


@hookimpl
def write_run_page(files: RunFiles, metrics: RunMetrics, config: dict[str, object]) -> None:
    """report.html: the run's figures, metrics, timings and configuration in one page."""
    from nlosfw.common import yaml_safe
    from nlosfw.common.errors import DataError
    from nlosfw.report.html_report import run_report
    from nlosfw.report.inputs import read_inside

    overrides: list[str] = []
    path = files.run_dir / ".hydra" / "overrides.yaml"
    if path.exists():
        try:  # Hydra's record of the command line, read only inside the run's folder
            text = read_inside(path, files.run_dir).decode("utf-8")
            overrides = [str(o) for o in yaml_safe.load(text) or []]
        except (DataError, UnicodeDecodeError) as err:
            log.warning("the page shows no overrides: %s", err)
    files.write_text("report.html", run_report(files.run_dir, metrics, config, overrides),
                     kind="report")

"""Reports: a run's figures and page, a sweep's report, the sparsity study, the comparison
with published numbers.

The only package that imports matplotlib (when a figure is drawn, never at import). A
run's report files are written by the report plugin (:mod:`~nlosfw.report.hooks`, a
subscriber to the run hooks); a sweep's by :func:`write_report`
(``python -m nlosfw report DIR``).

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these.
"""

from typing import TYPE_CHECKING

from nlosfw.common.deprecation import moved_names
from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.report.published_numbers import published_comparison
    from nlosfw.report.records import RunRecord, find_runs, read_run
    from nlosfw.report.study import Stat, StudyRow, study_figure, study_rows
    from nlosfw.report.sweep import write_report
    from nlosfw.report.tables import format_cell, markdown_table

__all__ = [
    "RunRecord",
    "Stat",
    "StudyRow",
    "find_runs",
    "format_cell",
    "markdown_table",
    "read_run",
    "study_figure",
    "study_rows",
    "published_comparison",
    "write_report",
]

#: The names this package exported before the thesis became one source of published numbers.
MOVED = {"thesis_comparison": "nlosfw.report:published_comparison"}

_lazy_getattr, __dir__ = lazy_exports(__name__, __file__)
__getattr__ = moved_names(__name__, MOVED, _lazy_getattr)

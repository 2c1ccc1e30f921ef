"""Our numbers next to the thesis's (Tables 4.1 and 5.1), for runs of the thesis presets.

A preset puts the reference values in its config under ``thesis.rows``, keyed by the
field-model source they compare with (``model`` or an entry of ``compare``)::

    thesis:
      figure: "5.4"
      rows:
        model: {table: "5.1", experiment: "Figure 5.4", loss: 0.0032978356,
                training_seconds: 673.98}
"""

from __future__ import annotations

from collections.abc import Sequence

from nlosfw.common.config import Scalar
from nlosfw.report.records import RunRecord
from nlosfw.report.tables import markdown_table

_TABLE_41 = ("experiment", "parameters (ours)", "parameters (thesis)", "data size (ours)",
             "data size (thesis)", "parameters/data % (ours)", "parameters/data % (thesis)",
             "run")
_TABLE_51 = ("hidden scene", "loss L2 (ours)", "loss L2 (thesis)", "training s (ours)",
             "training s (thesis)", "steps (ours)", "steps (thesis)", "run")


def _fmt(value: Scalar, spec: str = ".4g") -> str:
    if value is None:
        return "-"
    if isinstance(value, (int, float)):
        return format(value, spec)
    return str(value)


def thesis_comparison(records: Sequence[RunRecord]) -> str:
    """Markdown tables in the thesis's format, ours next to the published values."""
    table41: list[tuple[str, ...]] = []
    table51: list[tuple[str, ...]] = []
    for record in records:
        rows = record.thesis.get("rows") or {}
        for source, ref in rows.items():
            ours = record.metrics.field_entry(source)
            if str(ref.get("table")) == "4.1":
                params = None if ours is None else ours.n_parameters
                data = None if ours is None else ours.training_values
                ratio = 100.0 * params / data if params and data else None
                table41.append((ref.get("experiment", ""), _fmt(params, "d"),
                                _fmt(ref.get("parameters"), "d"), _fmt(data, "d"),
                                _fmt(ref.get("data_size"), "d"), _fmt(ratio, ".2f"),
                                _fmt(ref.get("ratio_percent"), ".2f"), record.name))
            elif str(ref.get("table")) == "5.1":
                fit = None if ours is None else ours.fit
                table51.append((ref.get("experiment", ""),
                                _fmt(None if fit is None else fit.final_loss),
                                _fmt(ref.get("loss")),
                                _fmt(None if fit is None else fit.seconds, ".1f"),
                                _fmt(ref.get("training_seconds"), ".1f"),
                                _fmt(None if fit is None else fit.steps, "d"), "100000",
                                record.name))
    out = []
    if table41:
        out.append("### Table 4.1: parameters and compression\n\n"
                   + markdown_table(_TABLE_41, table41)
                   + "\nThe thesis's percentages do not follow from its own parameter and data "
                   "counts (942/2048 = 46.0 %, 914/2048 = 44.6 %); ours are computed.\n")
    if table51:
        out.append("### Table 5.1: losses and training times\n\n"
                   + markdown_table(_TABLE_51, table51)
                   + "\nLosses are mean squared errors on data normalised into (-1, 1). The "
                   "thesis trained 100,000 full-batch epochs (about 675 s per scene on its "
                   "hardware); our defaults train far fewer minibatch steps on 2 CPU cores.\n")
    return "\n".join(out)

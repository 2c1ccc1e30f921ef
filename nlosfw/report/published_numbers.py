"""The run's numbers next to published ones: the tables of a run's ``published``.

A preset puts the numbers a source published into ``published.<table>``
(:class:`~nlosfw.pipeline.settings.PublishedTable`): a title, a note, and rows keyed by
the field-model source they compare with (``model`` or a ``compare`` label), each number
at the place metrics.json's ``field.<source>`` holds the run's own::

    published:
      thesis_table_5_1:
        title: "Thesis, Table 5.1: losses and training times"
        rows:
          model: {label: "Figure 5.4", fit: {final_loss: 0.0032978356, seconds: 673.98}}

:func:`published_comparison` makes one markdown table per published table the records
name, each published number beside the run's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from nlosfw.common.config import Scalar
from nlosfw.pipeline.metrics import FieldMetrics
from nlosfw.pipeline.settings import PublishedTable, row_numbers
from nlosfw.report.records import RunRecord
from nlosfw.report.tables import markdown_table

#: The file a run's comparison is written to (by the report plugin).
FILE_NAME = "published_numbers.md"


def _cell(value: object) -> str:
    if value is None:
        return "-"
    return format(value, ".4g") if isinstance(value, float) else str(value)


def ours(entry: FieldMetrics | None, path: str) -> Scalar:
    """The run's number at ``path`` (dotted) of its field-model entry, None where it has none."""
    node: object = entry
    for key in path.split("."):
        node = getattr(node, key, None)
    return node if isinstance(node, (int, float)) else None


def published_comparison(records: Sequence[RunRecord]) -> str:
    """Markdown: for each published table the records name (in the order they name them),
    one row per run and source, each published number beside the run's own."""
    tables: dict[str, tuple[PublishedTable, list[tuple[RunRecord, str, Mapping[str, object]]]]]
    tables = {}
    for record in records:
        for name, table in record.published.items():
            rows = tables.setdefault(name, (table, []))[1]
            rows += [(record, source, row) for source, row in table.rows.items()]
    out = []
    for name, (table, rows) in tables.items():
        paths = list(dict.fromkeys(path for _, _, row in rows
                                   for path, _ in row_numbers(row)))
        header = ["row", *(f"{p} ({which})" for p in paths for which in ("ours",
                                                                          "published")),
                  "run"]
        cells = []
        for record, source, row in rows:
            published = dict(row_numbers(row))
            entry = record.metrics.field_entry(source)
            cells.append([str(row.get("label", source)),
                          *(_cell(v) for p in paths
                            for v in (ours(entry, p), published.get(p))),
                          record.name])
        text = f"### {table.title or name}\n\n" + markdown_table(header, cells)
        out.append(text + (f"\n{' '.join(table.note.split())}\n" if table.note else ""))
    return "\n".join(out)

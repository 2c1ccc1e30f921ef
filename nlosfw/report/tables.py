"""Tables for reports (runs, sweeps, published numbers): markdown, and their cells."""

from __future__ import annotations

from collections.abc import Sequence

from nlosfw.common.config import Scalar
from nlosfw.common.text import markdown, shortened


def format_cell(value: Scalar) -> str:
    """A table cell: empty for None, 4 significant digits for a float, else ``str`` (at most
    :data:`~nlosfw.common.text.MAX_SHOWN` characters of it)."""
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return shortened(str(value))


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A markdown table (cells escaped: no raw HTML, no links, '|' kept in its cell)."""
    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(markdown(c) for c in cells) + " |"

    return "\n".join([line(header), "|" + "---|" * len(header), *map(line, rows)]) + "\n"

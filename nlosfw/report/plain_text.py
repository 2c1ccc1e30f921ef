"""Figures show their text literally: file names, scene names and labels from runs are
untrusted, and a ``$...$`` in one would otherwise be parsed by matplotlib's maths parser
(an error there means no figure and no report)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from matplotlib import rc_context
from matplotlib.figure import Figure
from matplotlib.text import Text


def literal_text(fig: Figure) -> Figure:
    """``fig`` with maths parsing turned off for every text in it (titles, labels, tick
    labels, legends); call before anything lays the figure out or saves it."""
    for text in fig.findobj(Text):
        text.set_parse_math(False)
    return fig


def save_literal(make: Callable[[], Figure], path: Path, dpi: int) -> None:
    """Make the figure and save it as PNG at ``dpi`` with maths parsing off for every text
    made meanwhile (as :func:`literal_text`, without walking the figure's artists: every
    tick's label, which drawing makes anyway)."""
    with rc_context({"text.parse_math": False}):
        make().savefig(path, dpi=dpi, format="png")

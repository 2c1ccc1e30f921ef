"""Untrusted text at every output: file names, scene names and directories reach
figure titles, the console, HTML links, CSV cells and Markdown. Each output shows them
literally: no maths parsing, no markup, no terminal escape sequences, no script links, no
spreadsheet formulas, no raw HTML."""

from __future__ import annotations

import csv
import io
import json
import re

import pytest
from rich.console import Console

from nlosfw.capture.hdf5 import write_capture
from nlosfw.common import text
from nlosfw.report.html_report import _files
from nlosfw.report.sweep import csv_text
from nlosfw.report.tables import markdown_table
from nlosfw.testing import fixtures

ESC = "\x1b"
#: A file name a careless user or an attacker could give: maths, markup, an escape sequence.
HOSTILE = f"a$x^2$ [/] [bold]b{ESC}[31m{ESC}]0;title\x07"


def rendered(*items: object) -> str:
    """What a (non-terminal) rich console prints for ``items``."""
    buffer = io.StringIO()
    console = Console(file=buffer, width=300, color_system=None)
    for item in items:
        console.print(item)
    return buffer.getvalue()


# -------------------------------------------------------------------- the console
@pytest.mark.parametrize("value", ["[/]", "x[/]y", "[bold]b[/bold]", "C:\\[red]", "a\\",
                                   "[link=javascript:alert(1)]x[/link]", "[@click]x"])
def test_console_text_prints_literally(value):
    assert rendered(text.console_text(value)) == value + "\n"


def test_console_text_removes_escape_sequences():
    shown = rendered(text.console_text(HOSTILE))
    assert ESC not in shown and "\x07" not in shown
    assert shown == "a$x^2$ [/] [bold]b\\x1b[31m\\x1b]0;title\\x07\n"


# --------------------------------------------------------------------- figures
def test_figure_text_is_never_parsed_as_maths(tmp_path):
    """``plain_title`` escapes what a figure would parse as maths; the figures apply it to
    every untrusted text (tests/test_figure_text.py)."""
    from matplotlib.figure import Figure

    def figure(title=lambda t: t) -> Figure:
        fig = Figure(figsize=(3, 2), layout="constrained")
        ax = fig.add_subplot()
        ax.set_title(title(r"scene $\frac{1}{$ " + HOSTILE))
        fig.suptitle(title(r"capture a$b$c$\undefinedcommand$.hdf5"))
        return fig

    with pytest.raises(ValueError):      # what matplotlib does with it by default
        figure().savefig(tmp_path / "parsed.png")
    literal = figure(text.plain_title)
    literal.savefig(tmp_path / "literal.png")
    assert (tmp_path / "literal.png").stat().st_size > 0
    suptitle = literal.texts[0]             # what it draws, and not as maths
    assert suptitle._preprocess_math(suptitle.get_text()) == (
        r"capture a$b$c$\undefinedcommand$.hdf5", False)


# ------------------------------------------------------------------------- HTML
def test_report_html_links_are_relative_and_quoted(tmp_path):
    for name in ("javascript:alert(1)", "data:text,x", 'q"><img src=x onerror=y>'):
        (tmp_path / name).write_text("x")
    html = _files(tmp_path)
    links = re.findall(r'href="([^"]*)"', html)
    assert sorted(links) == ["./data%3Atext%2Cx", "./javascript%3Aalert%281%29",
                             "./q%22%3E%3Cimg%20src%3Dx%20onerror%3Dy%3E"]
    assert "<img" not in html
    assert text.href("figures/a b.png") == "./figures/a%20b.png"


# -------------------------------------------------------------------------- CSV
def test_csv_string_cells_cannot_be_formulas():
    rows = [["=HYPERLINK(\"http://x\",\"y\")", "+1", "-cmd", "@SUM(A1)", "\t=1", "plain"],
            [-1.5, 3, 0.0, "-", "a=b", None],
            ["-13.7", "-1e-05", "-inf", "-1+1", "-2-cmd", "-.5"]]
    written = csv_text(["run", "b", "c", "d", "e", "f"], rows)
    parsed = list(csv.reader(io.StringIO(written)))
    assert parsed[1] == ["'=HYPERLINK(\"http://x\",\"y\")", "'+1", "'-cmd", "'@SUM(A1)",
                         "'\t=1", "plain"]
    assert parsed[2] == ["-1.5", "3", "0.0", "'-", "a=b", ""]    # numbers untouched
    # numbers the reports wrote as text stay numbers; anything more is text
    assert parsed[3] == ["-13.7", "-1e-05", "-inf", "'-1+1", "'-2-cmd", "-.5"]


# --------------------------------------------------------------------- Markdown
def test_markdown_cells_carry_no_html_or_links():
    table = markdown_table(["run", "value"], [["<script>alert(1)</script>", "[x](javascript:y)"],
                                              ["a|b", "`code`"]])
    assert "<script>" not in table and "&lt;script&gt;" in table
    assert "[x](" not in table and r"\[x\](javascript:y)" in table
    assert r"a\|b" in table and r"\`code\`" in table


# ----------------------------------------------------------------- scene_info
def test_json_safe_converts_yaml_only_types():
    import datetime

    value = {datetime.date(2024, 1, 2): frozenset({"b", "a"}),
             "t": (datetime.datetime(2024, 1, 2, 3, 4, 5), b"hi")}
    assert text.json_safe(value) == {"2024-01-02": ["a", "b"],
                                     "t": ["2024-01-02T03:04:05", "aGk="]}


# ------------------------------------------------------------------- end to end
#: Every kind of figure a run draws (one single-frequency pair, not two), at a small dpi:
#: the titles are laid out, and would be maths-parsed, whatever the dpi and the count, and
#: drawing the figures is most of such a run's time.
FIGURES = ("figures.enabled=true", "figures.dpi=40", "reconstruction.single_frequency_images=1")
def test_a_hostile_capture_name_and_run_dir_on_the_command_line(workdir, tools):
    """``$...$``, ``[/]`` and an escape sequence in the capture's file name, ``[/]`` in
    hydra.run.dir: the run completes with its figures, and nothing raw reaches the console."""
    name = f"a$x^2$ [/] b{ESC}[31m.hdf5"
    path = write_capture(workdir / name, fixtures.tiny_capture())
    result = tools.run(f"capture.path='{path}'", *tools.QUICK[1:], *FIGURES,
                       "hydra.run.dir='out/[/]run'")
    assert result.returncode == 0, result.stderr
    run_dir = workdir / "out" / "[" / "]run"
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["status"] == "completed"
    assert sorted(p.name for p in (run_dir / "figures").glob("*.png"))
    assert ESC not in result.stdout + result.stderr
    html = (run_dir / "report.html").read_text()
    assert all(link.startswith("./") for link in re.findall(r'href="([^"#]*)"', html))


def test_maths_in_the_scene_name_does_not_break_figures(workdir, tools):
    result = tools.run("scene=tiny", "scene.name='tiny $\\frac{1}{$ [/]'", *tools.QUICK[1:],
                       *FIGURES, "hydra.run.dir=out")
    assert result.returncode == 0, result.stderr
    assert json.loads((workdir / "out" / "metrics.json").read_text())["status"] == "completed"
    assert sorted(p.name for p in (workdir / "out" / "figures").glob("*.png"))

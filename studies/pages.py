"""What every study's ``run.py`` shares: its results file (the scores, with the machine,
commit and date they were measured on), the generated part of its page (between
``BEGIN`` and ``END``), the index ``studies/README.md`` and the command line
``run | collect | render``.

A study's ``render`` is a pure function of its ``results.json``: the page's text outside the
markers is written by hand and kept; inside them it is exactly what ``render`` writes, so
``tests/project/test_studies.py`` can rebuild every page and compare it byte for byte.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nlosfw.common import markdown

STUDIES = Path(__file__).resolve().parent
ROOT = STUDIES.parent
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
#: What a study's results file says where a value was never recorded.
NOT_RECORDED = "not recorded"
#: The studies, in the index's order (each a folder with README.md, run.py, results.json).
NAMES = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
         "physics_terms_measured", "classical_imagers_measured")


def commit() -> str:
    """The checkout's commit (``-dirty`` when files differ), or ``NOT_RECORDED``."""
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--abbrev=12"],
                             cwd=ROOT, capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return NOT_RECORDED
    return out.stdout.strip() or NOT_RECORDED


def recorded(note: str = "") -> dict[str, str]:
    """The ``recorded`` block of a results file collected now: this machine, the
    checkout's commit and today's date (UTC)."""
    machine = f"{platform.platform()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
    return {"machine": f"{machine}; {note}" if note else machine, "commit": commit(),
            "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")}


def read_results(folder: Path) -> dict[str, Any]:
    """A study's results.json."""
    data: dict[str, Any] = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    return data


def write_results(folder: Path, results: Mapping[str, Any]) -> Path:
    """Write a study's results.json (checked to carry its ``recorded`` block)."""
    missing = {"machine", "commit", "date"} - set(results.get("recorded", {}))
    if missing:
        raise ValueError(f"{folder.name}/results.json: recorded lacks {sorted(missing)}")
    path = folder / "results.json"
    temporary = path.with_name("results.json.tmp")
    temporary.write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n",
                         encoding="utf-8")
    temporary.replace(path)
    return path


def replace_generated(page: Path, text: str) -> None:
    """Replace the text between the page's markers with ``text``."""
    old = page.read_text(encoding="utf-8")
    pattern = re.compile(re.escape(BEGIN) + r"\n.*?" + re.escape(END), re.S)
    if not pattern.search(old):
        raise SystemExit(f"{page}: markers {BEGIN} ... {END} not found")
    page.write_text(pattern.sub(lambda _: f"{BEGIN}\n{text.rstrip()}\n{END}", old, count=1),
                    encoding="utf-8")


def recorded_line(results: Mapping[str, Any]) -> str:
    """One sentence: where and when the numbers were measured (the machine, commit and date
    escaped for Markdown: a user's ``--ran-on`` text ends up there)."""
    r = {k: markdown(v) for k, v in results["recorded"].items()}
    return (f"Measured on: {r['machine']}. Commit: {r['commit']}. Date: {r['date']}. "
            f"Source: {results.get('source', NOT_RECORDED)}.")


def render_index(studies: Path = STUDIES) -> None:
    """The generated table of ``studies/README.md``: each study's question and its last run."""
    rows = ["| study | question | date | commit | machine |", "|---|---|---|---|---|"]
    for name in NAMES:
        results = read_results(studies / name)
        r = {k: markdown(v) for k, v in results["recorded"].items()}
        rows.append(f"| [{name}]({name}/README.md) | {results['question']} | {r['date']} | "
                    f"{r['commit']} | {r['machine']} |")
    replace_generated(studies / "README.md", "\n".join(rows))


def plain_figure_settings() -> dict[str, object]:
    """Matplotlib settings under which a study's figure is the same bytes on every render
    with the same libraries (no date, a fixed SVG id salt)."""
    return {"svg.hashsalt": "nlosfw-studies", "svg.fonttype": "path"}


def save_figure(fig: Any, path: Path) -> None:
    """Save ``fig`` as SVG without a date (reproducible with the same matplotlib)."""
    fig.savefig(path, format="svg", metadata={"Date": None, "Creator": None})


@dataclass(frozen=True)
class Study:
    """A study's folder and its three steps (see :func:`main`)."""

    folder: Path
    run: Callable[[argparse.Namespace], None]
    collect: Callable[[argparse.Namespace], dict[str, Any]]
    render: Callable[[dict[str, Any], Path], None]
    #: Adds the ``run`` and ``collect`` subcommands' own arguments.
    arguments: Callable[[argparse.ArgumentParser, argparse.ArgumentParser], None] | None = None
    description: str = ""


def main(study: Study, argv: Sequence[str] | None = None) -> int:
    """The command line of a study: ``run`` (launch it, then collect), ``collect`` (read
    the runs' scores into results.json) and ``render`` (rewrite the page's generated
    section and its figure from results.json; ``--into DIR`` renders a copy of the folder).
    With ``--out JSON``, ``run`` and ``collect`` write the results there and leave the page
    and results.json as they are."""
    parser = argparse.ArgumentParser(description=study.description)
    sub = parser.add_subparsers(dest="command", required=True)
    run_parser = sub.add_parser("run", help="launch the study, then collect and render it")
    collect_parser = sub.add_parser("collect", help="read finished runs into results.json")
    render_parser = sub.add_parser("render", help="rewrite the page from results.json")
    render_parser.add_argument("--into", type=Path, default=study.folder,
                               help="the study folder to render (default: this one)")
    if study.arguments is not None:
        study.arguments(run_parser, collect_parser)
    args = parser.parse_args(argv)
    if args.command == "render":
        study.render(read_results(args.into), args.into)
        render_index(args.into.parent)
        return 0
    if args.command == "run":
        study.run(args)
    results = study.collect(args)
    out = getattr(args, "out", None)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(results, indent=1, ensure_ascii=False) + "\n",
                       encoding="utf-8")
    else:
        write_results(study.folder, results)
        study.render(results, study.folder)
        render_index(study.folder.parent)
    return 0

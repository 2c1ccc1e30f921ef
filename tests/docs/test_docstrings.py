"""Module, class and function docstrings hold no measured numbers (decibels, seconds,
gigabytes, speed-ups): those belong to the study pages (``studies/<name>/README.md``), which
a docstring links instead, so the code's documentation cannot go stale with a rerun."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: A measured number: "7 dB", "0.6 s", "1.2 GB", "took 50", "2.7 times faster", "3x faster".
#: (Megabytes are left alone: the memory estimate's constants document where they were
#: measured, ``nlosfw.model.neural.memory``, and a size's format is shown as ``1.5 MB``.)
MEASURED = re.compile(r"\d\s*dB\b|\d(\.\d+)? s\b|\d\s*GB\b|\btook \d|"
                      r"\d(\.\d+)?\s*(x|×|times) (faster|slower)")
#: Docstrings whose number is not a measurement (an example of a label's format).
NOT_MEASURED = {("nlosfw/report/figures.py", "PSNR 31.2 dB, SSIM 0.812 vs true")}


def measured_numbers(path: Path) -> list[str]:
    """``<line>: <text>`` of each docstring line of ``path`` that holds a measured number."""
    relative = path.relative_to(ROOT).as_posix()
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                 ast.AsyncFunctionDef)):
            continue
        doc = ast.get_docstring(node, clean=False)
        if not doc:
            continue
        start = node.body[0].lineno
        for offset, line in enumerate(doc.splitlines()):
            if MEASURED.search(line) and not any(
                    relative == where and text in line for where, text in NOT_MEASURED):
                found.append(f"{relative}:{start + offset}: {line.strip()}")
    return found


def _sources() -> list[Path]:
    files = sorted((ROOT / "nlosfw").rglob("*.py"))
    for package in sorted((ROOT / "plugins").glob("*/nlosfw_*")):
        files += sorted(package.rglob("*.py"))
    return files


def test_no_docstring_holds_a_measured_number():
    files = _sources()
    assert len(files) > 100 and any("nlosfw_torch" in str(f) for f in files)
    found = [hit for path in files for hit in measured_numbers(path)]
    assert not found, "link the study page instead of the numbers:\n" + "\n".join(found)


def test_the_pattern_finds_measurements():
    for text in ("fitted 7 dB better", "takes 0.6 s each", "peak 2.6 GB", "the fit took 278",
                 "2.7 times faster", "1.6x faster"):
        assert MEASURED.search(text), text
    for text in ("cos^k of the angle", "every 4th sample", "s the scene operator's", "16x"):
        assert not MEASURED.search(text), text


def test_the_study_pages_a_docstring_names_are_studies():
    studies = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
               "physics_terms_measured", "classical_imagers_measured")
    named = {name for path in _sources()
             for name in re.findall(r"studies/(\w+)/README\.md", path.read_text())}
    assert named and named <= set(studies), sorted(named - set(studies))
    if (ROOT / "studies").is_dir():
        assert all((ROOT / "studies" / name / "README.md").is_file() for name in named)

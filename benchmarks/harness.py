"""The one harness of the speed and memory benchmarks: timing (the best of several
wall-clock runs), the machine and commit a result was measured on, the tables the scripts
print (rich), and the results file each script writes with the key set it declares.

The machines' cores are shared, so the minimum over repeats is the least disturbed
measurement. Scripts in ``benchmarks/<package>/`` import it after putting this folder on
``sys.path`` (``sys.path.insert(0, str(Path(__file__).resolve().parents[1]))``).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from rich.console import Console
from rich.table import Table

T = TypeVar("T")

#: Where every benchmark writes its results (``<name>.json``).
RESULTS_DIR = Path(__file__).resolve().parent / "results"
ROOT = RESULTS_DIR.parents[1]


def best_of(call: Callable[[], T], repeat: int = 1) -> tuple[float, T]:
    """(minimum wall-clock seconds over ``repeat`` calls of ``call``, the last result)."""
    seconds = float("inf")
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        result = call()
        seconds = min(seconds, time.perf_counter() - start)
    return seconds, result


def commit() -> str:
    """The checkout's commit (with ``-dirty`` when files differ from it), or
    ``"not recorded"`` outside a git checkout."""
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--abbrev=12"],
                             cwd=ROOT, capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return "not recorded"
    return out.stdout.strip() or "not recorded"


def machine(**extra: object) -> dict[str, object]:
    """The machine of a results file: its CPUs, platform, Python and the commit measured,
    then ``extra`` (the versions of the libraries measured, a note)."""
    return {"cpus": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), "commit": commit(), **extra}


def print_table(title: str, columns: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Print ``rows`` (already formatted cells) under ``columns``, right-aligned."""
    table = Table(title=title)
    for column in columns:
        table.add_column(column, justify="right")
    for row in rows:
        table.add_row(*(str(cell) for cell in row))
    Console().print(table)


def print_speedups(title: str, rows: Mapping[str, Mapping[str, Any]], new: tuple[str, str]
                   ) -> None:
    """Print each backend's baseline and new seconds (``rows[backend]["baseline_s"]`` and
    the key ``new[1]``, in the column ``new[0]``), the speed-up and the gradients'
    mismatch."""
    print_table(title, ("backend", "baseline (s)", new[0], "speed-up", "gradient mismatch"),
                [(backend, f"{row['baseline_s']:.3f}", f"{row[new[1]]:.3f}",
                  f"{row['speedup']:.2f}x", f"{row['gradient_mismatch']:.1e}")
                 for backend, row in rows.items()])


def write_results(path: Path, results: Mapping[str, object], keys: Collection[str],
                  optional: Collection[str] = (), indent: int = 2) -> Path:
    """Write ``results`` as JSON to ``path`` (normally ``RESULTS_DIR / "<name>.json"``) after
    checking that its top-level keys are the script's declared ``keys`` (its
    ``RESULT_KEYS``) and at most ``optional`` ones besides (its ``OPTIONAL_KEYS``);
    tests/project/test_benchmarks.py compares the same declarations with the committed files."""
    missing, extra = set(keys) - set(results), set(results) - set(keys) - set(optional)
    if missing or extra:
        raise ValueError(f"{path.name}: the results' keys {sorted(results)} are not the "
                         f"declared RESULT_KEYS {sorted(keys)} (optional: {sorted(optional)})")
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps(results, indent=indent, default=float) + "\n",
                         encoding="utf-8")
    temporary.replace(path)
    return path

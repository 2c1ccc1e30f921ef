"""Start-up benchmark: ``import nlosfw`` and ``python -m nlosfw plugins``.

Each command runs in a fresh interpreter (in a neutral directory, so that each Python
imports its own installed nlosfw), ``--repeat`` times, alternating between this
environment's Python and, with ``--baseline PYTHON`` (an environment with another nlosfw
installed, e.g. main's), that one, so both see the same machine load. Reported: the best
and the median seconds, and the baseline / this ratio of the best: for ``import nlosfw``
the time of the import statement measured inside the interpreter, for the others the
wall-clock time of the process (``python -c pass`` is the interpreter's own start-up).
Results go to ``benchmarks/results/bench_import.json`` with the machine's load average.

    python benchmarks/pipeline/bench_import.py [--repeat 7] [--baseline /work/venv/bin/python]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, write_results

RESULTS = RESULTS_DIR / "bench_import.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('load_average_after', 'load_average_before', 'pythons', 'repeat', 'rows')
TIMED_IMPORT = ("import time; start = time.perf_counter(); import nlosfw; "
                "print(time.perf_counter() - start)")
COMMANDS = {"import nlosfw (in-process)": ["-c", TIMED_IMPORT],
            "python -c pass (start-up)": ["-c", "pass"],
            "python -m nlosfw plugins": ["-m", "nlosfw", "plugins"]}


def run_seconds(python: str, args: list[str]) -> float:
    """Seconds of one run of ``python args`` (which must succeed): what it prints for the
    timed import, else its wall-clock time."""
    start = time.perf_counter()
    out = subprocess.run([python, *args], check=True, capture_output=True, text=True,
                         cwd=tempfile.gettempdir(), env={**os.environ, "COLUMNS": "200"})
    wall = time.perf_counter() - start
    return float(out.stdout) if args[-1] == TIMED_IMPORT else wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--baseline", help="another environment's python (e.g. main's)")
    args = parser.parse_args()
    pythons = {"this": sys.executable, **({"baseline": args.baseline} if args.baseline else {})}
    rows = []
    load_before = os.getloadavg()
    for label, command in COMMANDS.items():
        times: dict[str, list[float]] = {who: [] for who in pythons}
        for _ in range(args.repeat):
            for who, python in pythons.items():   # alternate: both see the same load
                times[who].append(run_seconds(python, command))
        row: dict[str, object] = {"command": label}
        for who, seconds in times.items():
            row[f"{who}_best_s"] = round(min(seconds), 4)
            row[f"{who}_median_s"] = round(statistics.median(seconds), 4)
        if args.baseline:
            row["speedup"] = round(min(times["baseline"]) / min(times["this"]), 2)
        rows.append(row)
    columns = list(rows[0])
    print(" | ".join(f"{c:>24}" if i == 0 else f"{c:>16}" for i, c in enumerate(columns)))
    for row in rows:
        print(" | ".join(f"{row[c]!s:>24}" if i == 0 else f"{row[c]!s:>16}"
                         for i, c in enumerate(columns)))
    write_results(RESULTS, {"repeat": args.repeat, "pythons": pythons,
                            "load_average_before": load_before,
                            "load_average_after": os.getloadavg(), "rows": rows}, RESULT_KEYS)
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()

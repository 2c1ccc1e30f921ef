"""metrics.json speed: writing (``RunMetrics.dumps``) and reading
(``RunMetrics.from_json`` of the parsed file, ``RunMetrics.read``) one run's metrics.

With ``--baseline PYTHON`` the same measurement runs in that environment too (e.g. main's,
whose metrics were typed by hand-written dataclass code), in the same call. The document
is ``--metrics PATH`` or, by default, the metrics.json of a tiny run made first. Reported:
microseconds per call (best of ``--repeat`` batches). Results go to
``benchmarks/results/bench_json.json``.

    python benchmarks/pipeline/bench_json.py [--metrics PATH] [--baseline /work/venv/bin/python]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import timeit
from pathlib import Path

from harness import RESULTS_DIR, write_results

RESULTS = RESULTS_DIR / "bench_json.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('pythons', 'us_per_call')
TINY = ["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
        "transform.n_frequencies=21", "reconstruction.n_depths=4"]


def measure(path: Path, repeat: int, number: int) -> dict[str, float]:
    """Microseconds per call of writing and reading the metrics at ``path``."""
    from nlosfw.pipeline import RunMetrics

    text = path.read_text()
    data = json.loads(text)
    metrics = RunMetrics.from_json(data)
    if metrics.dumps() != text:
        raise SystemExit(f"{path}: dumps() does not give the file back byte for byte")
    calls = {"dumps": metrics.dumps, "from_json": lambda: RunMetrics.from_json(data),
             "read": lambda: RunMetrics.read(path)}
    return {name: round(min(timeit.repeat(call, repeat=repeat, number=number)) / number * 1e6,
                        1) for name, call in calls.items()}


def tiny_metrics(folder: Path) -> Path:
    subprocess.run([sys.executable, "-m", "nlosfw", *TINY, f"hydra.run.dir={folder}/run"],
                   check=True, capture_output=True, env={"NLOSFW_CACHE_DIR": str(folder / "c"),
                                                         "PATH": "/usr/bin:/bin"})
    return folder / "run" / "metrics.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--metrics", type=Path)
    parser.add_argument("--baseline", help="another environment's python (e.g. main's)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--number", type=int, default=200)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.metrics, args.repeat, args.number)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = args.metrics or tiny_metrics(Path(tmp))
        rows = {"this": measure(path, args.repeat, args.number)}
        if args.baseline:
            out = subprocess.run([args.baseline, __file__, "--child", "--metrics", str(path),
                                  "--repeat", str(args.repeat), "--number", str(args.number)],
                                 check=True, capture_output=True, text=True)
            rows["baseline"] = json.loads(out.stdout)
    print(f"{'us per call':>12} | " + " | ".join(f"{k:>10}" for k in rows["this"]))
    for who, row in rows.items():
        print(f"{who:>12} | " + " | ".join(f"{v:>10}" for v in row.values()))
    if "baseline" in rows:
        ratios = {k: round(rows["baseline"][k] / rows["this"][k], 2) for k in rows["this"]}
        print(f"{'speedup':>12} | " + " | ".join(f"{v:>10}" for v in ratios.values()))
        rows["speedup"] = ratios
    write_results(RESULTS, {"pythons": {"this": sys.executable, "baseline": args.baseline},
                            "us_per_call": rows}, RESULT_KEYS)
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()

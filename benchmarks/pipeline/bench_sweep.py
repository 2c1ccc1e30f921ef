"""Load benchmark: a sweep of many short jobs on one machine, sharing one cache.

``python -m nlosfw -m hydra/launcher=parallel`` (joblib, 2 workers) runs ``--jobs`` runs
of the tiny scene with Poisson noise: ``simulator.seed`` over ``jobs / 2`` values times
``model=interp,nearest``, so every capture and field in the cache is wanted by two jobs
running at the same time. Afterwards every job must have a completed ``metrics.json`` and
every cache entry must match its checksum. Reported: wall-clock time, jobs per minute.
Results go to ``benchmarks/results/bench_sweep.json`` with the machine's load average
before and after (jobs per minute drop in proportion when other work shares the cores).

    python benchmarks/pipeline/bench_sweep.py [--quick] [--jobs 200] [--launcher parallel]

The same sweep on a SLURM cluster: ``--launcher slurm`` (see the README, "Sweeps, reports,
clusters").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, write_results

from nlosfw.pipeline import cache_entries, file_digest

RESULTS = RESULTS_DIR / "bench_sweep.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('cache_entries', 'completed', 'corrupt_entries', 'jobs', 'jobs_per_minute',
               'launcher', 'machine', 'not_completed', 'seconds', 'temporaries')
JOB = ("scene=tiny", "scene.noise.model=poisson", "scene.noise.photons=1e5", "imager=fft",
       "figures.enabled=false", "transform.n_frequencies=21", "reconstruction.n_depths=4")


def sweep_command(jobs: int, sweep_dir: Path, launcher: str) -> list[str]:
    seeds = max(1, jobs // 2)
    return [sys.executable, "-m", "nlosfw", "-m", f"hydra/launcher={launcher}", *JOB,
            f"simulator.seed=range(0,{seeds})", "model=interp,nearest",
            f"hydra.sweep.dir={sweep_dir}"]


def check(sweep_dir: Path, cache_dir: Path, jobs: int) -> dict[str, Any]:
    """Every job's metrics present and completed; every cache entry whole."""
    statuses = []
    for num in range(jobs):
        path = sweep_dir / str(num) / "metrics.json"
        statuses.append(json.loads(path.read_text())["status"] if path.exists() else "missing")
    entries = cache_entries(cache_dir)
    corrupt = [str(e.path) for e in entries if not e.check.exists()
               or e.check.read_text().strip() != file_digest(e.path)]
    leftovers = [str(p) for p in list(sweep_dir.rglob("*.tmp*")) + list(cache_dir.rglob("*.tmp*"))]
    return {"completed": statuses.count("completed"), "not_completed": jobs - statuses.count(
        "completed"), "cache_entries": len(entries), "corrupt_entries": corrupt,
        "temporaries": leftovers}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help="16 jobs")
    parser.add_argument("--launcher", default="parallel",
                        help="hydra/launcher: parallel (joblib), slurm, slurm_local")
    args = parser.parse_args(argv)
    jobs = 16 if args.quick else args.jobs
    jobs -= jobs % 2
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        env = {**os.environ, "NLOSFW_CACHE_DIR": str(root / "cache"), "MPLBACKEND": "Agg"}
        load_before = os.getloadavg()[0]   # other jobs on the machine slow the sweep
        start = time.perf_counter()
        done = subprocess.run(sweep_command(jobs, root / "sweep", args.launcher), cwd=root,
                              env=env, capture_output=True, text=True, check=False)
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise SystemExit(f"the sweep failed ({done.returncode}):\n{done.stderr[-4000:]}")
        outcome = check(root / "sweep", root / "cache", jobs)
    results = {
        "jobs": jobs, "launcher": args.launcher, "seconds": round(seconds, 1),
        "jobs_per_minute": round(60 * jobs / seconds, 1), **outcome,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "load_average_before": round(load_before, 2),
                    "load_average_after": round(os.getloadavg()[0], 2)},
    }
    report(results)
    if not args.quick:
        write_results(RESULTS, results, RESULT_KEYS)
    ok = (outcome["not_completed"] == 0 and not outcome["corrupt_entries"]
          and not outcome["temporaries"])
    if not ok:
        raise SystemExit("the sweep left incomplete jobs, corrupt cache entries or temporaries")
    return results


def report(results: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"sweep of {results['jobs']} short jobs, {results['launcher']} "
                        f"launcher ({results['machine']['cpus']} cores), one shared cache")
    for column in ("jobs", "seconds", "jobs/min", "completed", "cache entries", "corrupt",
                   "temporaries left"):
        table.add_column(column)
    table.add_row(str(results["jobs"]), f"{results['seconds']:.1f}",
                  f"{results['jobs_per_minute']:.1f}", str(results["completed"]),
                  str(results["cache_entries"]), str(len(results["corrupt_entries"])),
                  str(len(results["temporaries"])))
    Console().print(table)


if __name__ == "__main__":
    main()

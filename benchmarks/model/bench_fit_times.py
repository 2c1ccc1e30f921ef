"""Fit times of field models on measured captures, per device (the study's
models within 120 s at 16x and 64x on 2 cores, and GPU times).

Each MODEL:DEVICE pair runs ``nlosfw.run`` on each capture (a file, or every ``.mat`` of
a folder) at each spatial step (``--steps``: 4 is 16x, 8 is 64x; grid, count splitting,
count-splitting seed 0, ``stop_after=predict``) with ``model.device=DEVICE`` for the torch
models, one run at a time, and records ``timings.fit`` of metrics.json, the run's wall
seconds and its CPU seconds (user + system of every thread and waited-for worker process:
on cores others share the wall time says as much about them as about the model, the CPU
time does not; a ``model=interp`` row is the run's cost without a fit). Prints a table
and writes ``benchmarks/results/fit_times_<label>.json``. How well those fits predict
the held-out measurements is a study: ``studies/sparse_scans_measured``.

    python benchmarks/model/bench_fit_times.py CAPTURE.mat siren_torch:cuda,siren_torch:cpu \
        --label h200
    python benchmarks/model/bench_fit_times.py ../shared/data/real siren_torch:cpu --steps 4,8
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, machine, write_results

ROOT = Path(__file__).resolve().parents[2]
#: The results files: ``fit_times_<label>.json`` (``--label``).
RESULTS_PREFIX = "fit_times_"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('machine', 'rows')
#: Keys written only by some modes.
OPTIONAL_KEYS = ('capture',)


def cpu_seconds() -> float:
    """User + system CPU seconds of this process (every thread) and its waited-for children."""
    own, children = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                          resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def one(capture: Path, model: str, device: str, step: int) -> dict[str, object]:
    """Fit seconds, wall seconds and CPU seconds of one model's run on one device."""
    from nlosfw import run

    extra = [f"model.device={device}"] if model.endswith("_torch") else []
    start, start_cpu = time.perf_counter(), cpu_seconds()
    out = run([f"capture.path={capture}", f"model={model}", "split.count_splitting=true",
               "split.count_splitting_seed=0", f"split.spatial_step={step}", "sampling=grid",
               "stop_after=predict", "figures.enabled=false", *extra],
              output_dir=Path(tempfile.mkdtemp()) / "run")
    metrics = json.loads((out.dir / "metrics.json").read_text())
    return {"capture": capture.name, "undersampling": step * step, "model": model,
            "device": device, "fit_seconds": metrics["timings"]["fit"],
            "wall_seconds": round(time.perf_counter() - start, 1),
            "cpu_seconds": round(cpu_seconds() - start_cpu, 1)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture", type=Path, help="a capture file or a folder of .mat files")
    parser.add_argument("pairs", help="MODEL:DEVICE[,MODEL:DEVICE ...]")
    parser.add_argument("--steps", default="4", help="spatial steps, e.g. 4,8 (16x, 64x)")
    parser.add_argument("--label", default="cpu", help="names the results file")
    args = parser.parse_args()
    captures = (sorted(args.capture.glob("*.mat")) if args.capture.is_dir()
                else [args.capture] if args.capture.is_file() else [])
    if not captures:
        print(f"capture: {args.capture} is neither a capture file nor a folder of .mat files")
        return 2
    try:
        steps = [int(s) for s in args.steps.split(",")]
    except ValueError:
        steps = []
    if not steps or min(steps) < 1:
        print(f"--steps: {args.steps!r} is not a comma-separated list of positive integers")
        return 2
    os.environ.setdefault("NLOSFW_CACHE_DIR", tempfile.mkdtemp())
    rows = []
    print(f"{'capture':32s} {'x':>3s} {'model':22s} {'device':6s} {'fit s':>8s} "
          f"{'wall s':>8s} {'CPU s':>8s}")
    for capture in captures:
        for step in steps:
            for pair in args.pairs.split(","):
                model, _, device = pair.partition(":")
                row = one(capture.resolve(), model, device or "cpu", step)
                rows.append(row)
                print(f"{capture.name:32s} {step * step:3d} {model:22s} {row['device']:6s} "
                      f"{row['fit_seconds']:8.1f} {row['wall_seconds']:8.1f} "
                      f"{row['cpu_seconds']:8.1f}", flush=True)
    out = write_results(RESULTS_DIR / f"{RESULTS_PREFIX}{args.label}.json",
                        {"machine": machine(), "rows": rows}, RESULT_KEYS, OPTIONAL_KEYS, indent=1)
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

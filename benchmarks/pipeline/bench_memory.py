"""Memory benchmark: the pre-run estimate against the measured peak RSS.

Each named configuration runs on the CPU as ``python -m nlosfw ...`` in a child process;
its peak resident set size is read from ``resource.getrusage(RUSAGE_CHILDREN)`` of a
wrapper process whose only child it is, once it has ended, and its estimate is the
plan's (:func:`nlosfw.compose.plan_run`: ``RunPlan.memory``, each model's part its own
estimate) of the same configuration, plus the interpreter and its libraries as the
process that made the plan holds them (its capture read, its backend imported), as the
run holds them too. The target: the
measured peak within [estimate / 1.5, 1.5 × estimate]. Results go to
``benchmarks/results/bench_memory.json``.

    nice -n 10 python benchmarks/pipeline/bench_memory.py [--only NAME ...]

The real capture (64 × 64 × 2048, the LCT release's ``data_diffuse_s.mat``) is read from
``$NLOSFW_REAL_DATA``, else ``../shared/data/real`` beside the repository; without it
those configurations are skipped. ``--only`` runs the configurations named and keeps the
other rows of the results file as they were.
It is heavy (a minute or more and over a gigabyte per configuration): run it alone.
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
from harness import RESULTS_DIR, write_results

REPO = Path(__file__).resolve().parents[2]
REAL_DIR = Path(os.environ.get("NLOSFW_REAL_DATA") or REPO.parent / "shared" / "data" / "real")
REAL = REAL_DIR / "data_diffuse_s.mat"
RESULTS = RESULTS_DIR / "bench_memory.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('machine', 'rows')
FAST = ("model=interp", "imager=fft", "figures.enabled=false")
#: A neural field model, its training cut to 300 steps (its memory does not grow with them).
SIREN = ("model=siren_torch", "model.steps=300", "imager=fft", "figures.enabled=false")

#: The physics model on the real-data study's 16x grid (its kernel spectra cached).
RSD_PRIOR = ("model=rsd_prior", "split.spatial_step=4", "imager=fft", "figures.enabled=false")
#: The neural hidden volume on the same grid with count splitting: its operator dominates.
NEURAL_VOLUME = ("model=neural_volume_torch", "split.spatial_step=4",
                 "split.count_splitting=true", "imager=fft", "figures.enabled=false")
#: The real-data study's default, which fits the neural volume beside three rsd_priors.
ENSEMBLE = ("model=ensemble_torch", *NEURAL_VOLUME[1:])

#: ``image FILE imager=NAME`` of the real capture: each imager's own arrays on top.
IMAGE = ("model=none", "output.keep=[reconstructions]", "figures.enabled=false")

#: name -> (overrides, needs the real capture)
CONFIGS: dict[str, tuple[tuple[str, ...], bool]] = {
    **{f"real-64x64x2048-image-{imager}": ((f"capture.path={REAL}", *IMAGE, f"imager={imager}"),
                                          True) for imager in ("fft", "lct", "fk", "fbp")},
    "real-64x64x2048": ((f"capture.path={REAL}", *FAST), True),
    "simulated-default": (FAST, False),
    "simulated-32x32x1024": (("scene.wall.resolution=[32,32]", "scene.time.bins=1024",
                              *FAST), False),
    "real-64x64x2048-siren_torch": ((f"capture.path={REAL}", *SIREN), True),
    "simulated-default-siren_torch": (SIREN, False),
    "simulated-default-siren_jax": (("model=siren_jax", *SIREN[1:]), False),
    "real-64x64x2048-rsd_prior-16x": ((f"capture.path={REAL}", *RSD_PRIOR), True),
    "real-64x64x2048-neural_volume_torch-16x": ((f"capture.path={REAL}", *NEURAL_VOLUME),
                                                True),
    "real-64x64x2048-neural_volume_torch-16x-random": (
        (f"capture.path={REAL}", *NEURAL_VOLUME, "sampling=random"), True),
    "real-64x64x2048-ensemble_torch-16x": (
        (f"capture.path={REAL}", *ENSEMBLE), True),
    "real-64x64x2048-ensemble_torch-16x-random": (
        (f"capture.path={REAL}", *ENSEMBLE, "sampling=random"), True),
}


def estimate(overrides: tuple[str, ...]) -> float:
    """The run's estimate (bytes): its plan's, made exactly as the command line makes it,
    and this process's resident memory once the plan is made (the program)."""
    from nlosfw.compose import plan_run
    from nlosfw.pipeline import memory_summary, process_memory
    from nlosfw.plugins import load_plugins

    plan = plan_run(list(overrides), load_plugins())
    print(memory_summary(plan.memory), file=sys.stderr)
    return plan.memory.total + process_memory()


def estimate_in_child(name: str) -> float:
    """:func:`estimate` of configuration ``name`` in a fresh process (whose resident memory,
    counted as the program's, is then a run's: nothing else loaded)."""
    done = subprocess.run([sys.executable, __file__, "--estimate", name], capture_output=True,
                          text=True, check=True)
    return float(done.stdout.split()[-1])


#: Runs the command given to it and prints its peak RSS (KiB): each run measured alone.
_WRAPPER = ("import resource, subprocess, sys; "
            "status = subprocess.run(sys.argv[1:], capture_output=True).returncode; "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, status)")


def measure(overrides: tuple[str, ...]) -> tuple[float, float, int]:
    """(peak RSS in bytes, seconds, exit status) of one run, in a child process of a
    wrapper process of its own (so that no other run's peak is counted)."""
    with tempfile.TemporaryDirectory(prefix="nlosfw-bench-memory-") as tmp:
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "nlosfw",
                               *overrides, f"hydra.run.dir={tmp}/run",
                               f"cache.dir={tmp}/cache"],
                              capture_output=True, text=True, check=True)
        seconds = time.perf_counter() - start
    peak_kib, status = (int(v) for v in done.stdout.split())
    return peak_kib * 1024.0, seconds, status


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=sorted(CONFIGS), default=None)
    parser.add_argument("--estimate", choices=sorted(CONFIGS), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.estimate:
        print(estimate(CONFIGS[args.estimate][0]))
        return 0
    kept = json.loads(RESULTS.read_text())["rows"] if args.only and RESULTS.exists() else []
    rows = [r for r in kept if r["name"] not in args.only]  # rows not run this time stay
    for name, (overrides, real) in CONFIGS.items():
        if args.only and name not in args.only:
            continue
        if real and not REAL.exists():
            print(f"{name}: skipped ({REAL} is absent)")
            continue
        est = estimate_in_child(name)
        peak, seconds, status = measure(overrides)
        ratio = peak / est if est else float("inf")
        rows.append({"name": name, "overrides": list(overrides), "estimate_bytes": est,
                     "peak_rss_bytes": peak, "ratio": ratio, "seconds": seconds,
                     "exit_status": status, "within_target": 1 / 1.5 <= ratio <= 1.5})
    print(f"{'configuration':<32}{'estimate MB':>13}{'peak RSS MB':>13}{'ratio':>8}  ok")
    for r in rows:
        print(f"{r['name']:<32}{r['estimate_bytes'] / 1e6:>13.0f}"
              f"{r['peak_rss_bytes'] / 1e6:>13.0f}{r['ratio']:>8.2f}  "
              f"{'yes' if r['within_target'] else 'NO'}")
    write_results(RESULTS, {"machine": platform.platform(), "rows": rows}, RESULT_KEYS,
                  indent=1)
    return 0 if rows and all(r["within_target"] and r["exit_status"] == 0 for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())

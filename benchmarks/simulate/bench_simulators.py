"""Benchmark: embree vs mitsuba on thesis_two_planes (64 x 64 sensors, 2048 bins).

For each simulator and several sample counts: wall time, rays (embree) or paths
(mitsuba) per second, and the relative L2 error of H against a high-sample
reference (embree with many more samples and another seed; the scene has no
shadowing, so the analytic quadrature is reported against it as a cross-check).
Targets:

* embree reaches 3% relative error at least 2x faster than mitsuba;
* embree's whole simulation runs at >= half the raw embreex occlusion throughput,
  measured in the same run on the same scene's queries (same threads);
* peak memory (max RSS of this process) stays under 4 GB.

Timings on a shared machine vary: the load average is recorded with the results.

    python benchmarks/simulate/bench_simulators.py            # full run (about 5-10 minutes)
    python benchmarks/simulate/bench_simulators.py --quick    # smoke run (well under a minute)
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, write_results

from nlosfw.simulate import builtin_scene
from nlosfw.testing import relative_l2 as rel_l2
from nlosfw.testing import rendered

TARGET_ERROR = 0.03
RESULTS = RESULTS_DIR / "bench_simulators.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('analytic_cross_check', 'bin_width_m', 'bins', 'machine',
               'mitsuba_vs_reference_profiles', 'quick', 'raw_embree', 'reference', 'runs',
               'scene', 'sensors', 'targets', 'threads', 'total_seconds')


def peak_rss_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20   # Linux: KiB


def time_to_error(times: list[float], errors: list[float],
                  target: float) -> tuple[float | None, str]:
    """Seconds to reach ``target`` error.

    Interpolated in log-log between the two runs that bracket it; otherwise
    extrapolated along the least-squares line of log(error) against log(time)
    through every run (robust to one noisy timing on a shared machine).
    """
    pts = sorted(zip(times, errors, strict=True))
    if len(pts) < 2:
        return None, "too few points"
    for (t0, e0), (t1, e1) in zip(pts, pts[1:], strict=False):
        if e1 <= target <= e0 and e1 < e0:
            slope = np.log(e1 / e0) / np.log(t1 / t0)
            return float(t0 * (target / e0) ** (1 / slope)), "interpolated"
    slope, intercept = np.polyfit(np.log([t for t, _ in pts]), np.log([e for _, e in pts]), 1)
    if slope >= 0:
        return None, "error does not fall with time"
    where = "below the fastest" if target > pts[0][1] else "beyond the slowest"
    return float(np.exp((np.log(target) - intercept) / slope)), (
        f"extrapolated {where} run (error ~ time^{slope:.2f})")


def profile_agreement(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Mean per-sensor correlation of the time profiles and the largest onset difference."""
    pa = np.asarray(a, np.float64).reshape(a.shape[0], -1).T
    pb = np.asarray(b, np.float64).reshape(b.shape[0], -1).T
    za = (pa - pa.mean(1, keepdims=True)) / pa.std(1, keepdims=True)
    zb = (pb - pb.mean(1, keepdims=True)) / pb.std(1, keepdims=True)
    onset_a = np.argmax(pa / pa.max(1, keepdims=True) >= 0.01, axis=1)
    onset_b = np.argmax(pb / pb.max(1, keepdims=True) >= 0.01, axis=1)
    return {"mean_correlation": float((za * zb).mean(axis=1).mean()),
            "max_onset_difference_bins": int(np.abs(onset_a - onset_b).max())}


def raw_embree_throughput(scene: Any, threads: int, n_samples: int,
                          per_call: int = 1 << 18) -> dict[str, float]:
    """Occlusion rays/s of embreex alone on the simulation's own sensor-leg queries."""
    from nlosfw_embree.tracer import OcclusionTracer
    from nlosfw_embree.transport import Binning, SurfaceSamples, laser_side

    from nlosfw.simulate import scene_mesh, sobol_engine, surface_points

    mesh = scene_mesh(scene)
    tracer = OcclusionTracer(mesh)
    p, n, rho = surface_points(mesh, sobol_engine(np.random.default_rng(7)).random(n_samples))
    binning = Binning(scene.time.bins, scene.time.bin_width, t_start=0.0, ray_offset=1e-4)
    lit, _ = laser_side(SurfaceSamples(p, n, rho), scene.laser_spot_xyz(), tracer, binning)
    sensors = scene.wall.grid_xyz().reshape(-1, 3).astype(np.float32)
    origins = np.repeat(lit.origin[None], sensors.shape[0], axis=0).reshape(-1, 3)
    dirs = (sensors[:, None, :] - lit.position[None]).reshape(-1, 3).astype(np.float32)
    far = np.full(per_call, 1e30, np.float32)
    n_rays = origins.shape[0] - origins.shape[0] % per_call
    calls = [slice(i, i + per_call) for i in range(0, n_rays, per_call)]

    def work(my_calls: list[slice]) -> None:
        for sl in my_calls:
            tracer.occluded(origins[sl], dirs[sl], far)

    out = {}
    for label, t in (("threads", threads), ("one_thread", 1)):
        parts = [calls[k::t] for k in range(t)]
        best = np.inf
        for _ in range(3):
            start = time.perf_counter()
            workers = [threading.Thread(target=work, args=(part,)) for part in parts]
            for w in workers:
                w.start()
            for w in workers:
                w.join()
            best = min(best, time.perf_counter() - start)
        out[f"rays_per_second_{label}"] = n_rays / best
    out["rays"] = float(n_rays)
    return out


def run_embree(scene: Any, samples: int, seed: int, threads: int) -> dict[str, Any]:
    from nlosfw_embree.simulator import EmbreeSimulator

    sim = EmbreeSimulator({"samples": samples, "seed": seed, "threads": threads})
    start = time.perf_counter()
    capture = rendered(sim, scene)
    seconds = time.perf_counter() - start
    stats = capture.scene_info["render"]
    return {"H": capture.H, "seconds": seconds, "rays": stats["rays"],
            "rays_per_second": stats["rays"] / seconds}


def run_mitsuba(scene: Any, spp: int, seed: int, threads: int) -> dict[str, Any]:
    from nlosfw_mitsuba.simulator import MitsubaSimulator

    sim = MitsubaSimulator({"spp": spp, "seed": seed, "threads": threads})
    start = time.perf_counter()
    capture = rendered(sim, scene)
    seconds = time.perf_counter() - start
    paths = capture.scene_info["render"]["paths"]
    return {"H": capture.H, "seconds": seconds, "paths": paths,
            "paths_per_second": paths / seconds}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small smoke run")
    parser.add_argument("--threads", type=int, default=0, help="0: every available core")
    parser.add_argument("--no-mitsuba", action="store_true", help="skip the mitsuba runs")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)

    from nlosfw_embree.simulator import available_cores
    from rich.console import Console
    from rich.table import Table

    console = Console()
    threads = args.threads or available_cores()
    if args.quick:
        scene = builtin_scene("thesis_two_planes", wall={"resolution": [16, 16]},
                              time={"bins": 512, "bin_width": 0.012})
        embree_samples = [1 << 11, 1 << 12, 1 << 13, 1 << 14]
        mitsuba_spp = [1 << 10, 1 << 12, 1 << 14]
        reference_samples, raw_samples = 1 << 17, 1 << 11
    else:
        scene = builtin_scene("thesis_two_planes")
        embree_samples = [1 << 13, 1 << 14, 1 << 15, 1 << 16, 1 << 17]
        mitsuba_spp = [1 << 10, 1 << 12, 1 << 14, 1 << 15, 1 << 16]
        reference_samples, raw_samples = 1 << 19, 1 << 11
    nx, ny = scene.wall.resolution
    load_before = os.getloadavg()
    console.print(f"[bold]bench_simulators[/]: {scene.name}, {nx}x{ny} sensors, "
                  f"{scene.time.bins} bins of {scene.time.bin_width * 1000:g} mm, "
                  f"{threads} threads, load average {load_before[0]:.2f}")

    t0 = time.perf_counter()
    reference = run_embree(scene, reference_samples, seed=12345, threads=threads)
    console.print(f"reference: embree, {reference_samples} samples, "
                  f"{reference['seconds']:.1f} s")
    ref_H = reference["H"].astype(np.float64)
    from nlosfw.simulate import AnalyticSimulator

    start = time.perf_counter()
    analytic_H = rendered(AnalyticSimulator(), scene).H
    analytic = {"seconds": time.perf_counter() - start, "error": rel_l2(analytic_H, ref_H),
                "energy_ratio": float(analytic_H.sum(dtype=np.float64) / ref_H.sum())}

    raw = raw_embree_throughput(scene, threads, raw_samples)
    rows: list[dict[str, Any]] = []
    for samples in embree_samples:
        r = run_embree(scene, samples, seed=1, threads=threads)
        rows.append({"simulator": "embree", "setting": f"{samples} samples", "samples": samples,
                     "seconds": r["seconds"], "error": rel_l2(r["H"], ref_H),
                     "rays": r["rays"], "rays_per_second": r["rays_per_second"]})
        console.print(f"  embree {samples:>8} samples: {r['seconds']:7.2f} s, "
                      f"error {rows[-1]['error']:.4f}")
    raw_after = raw_embree_throughput(scene, threads, raw_samples)
    raw_rate = max(raw["rays_per_second_threads"], raw_after["rays_per_second_threads"])
    if not args.no_mitsuba:
        run_mitsuba(scene, 16, seed=0, threads=threads)          # compile Dr.Jit's kernels
        for spp in mitsuba_spp:
            r = run_mitsuba(scene, spp, seed=1, threads=threads)
            rows.append({"simulator": "mitsuba", "setting": f"{spp} spp", "spp": spp,
                         "seconds": r["seconds"], "error": rel_l2(r["H"], ref_H),
                         "paths": r["paths"], "paths_per_second": r["paths_per_second"],
                         **profile_agreement(r["H"], ref_H)})
            console.print(f"  mitsuba {spp:>7} spp: {r['seconds']:7.2f} s, "
                          f"error {rows[-1]['error']:.4f}")

    def sweep(name: str) -> tuple[float | None, str]:
        mine = [r for r in rows if r["simulator"] == name]
        return time_to_error([r["seconds"] for r in mine], [r["error"] for r in mine],
                             TARGET_ERROR)

    t_embree, how_embree = sweep("embree")
    t_mitsuba, how_mitsuba = sweep("mitsuba") if not args.no_mitsuba else (None, "skipped")
    embree_rows = [r for r in rows if r["simulator"] == "embree"]
    sim_rate = max(r["rays_per_second"] for r in embree_rows)
    largest = max(embree_rows, key=lambda r: r["samples"])
    # the reference error, from the measured convergence rate of the sweep
    fit = np.polyfit(np.log([r["samples"] for r in embree_rows]),
                     np.log([r["error"] for r in embree_rows]), 1)
    ref_error = float(np.exp(np.polyval(fit, np.log(reference_samples))))
    speedup = (t_mitsuba / t_embree) if (t_mitsuba and t_embree) else None
    result = {
        "scene": scene.name, "sensors": [nx, ny], "bins": scene.time.bins,
        "bin_width_m": scene.time.bin_width, "threads": threads, "quick": args.quick,
        "reference": {"simulator": "embree", "samples": reference_samples,
                      "seconds": reference["seconds"], "estimated_error": ref_error,
                      "convergence_exponent": float(fit[0])},
        "analytic_cross_check": analytic,
        "mitsuba_vs_reference_profiles": next(
            ({k: r[k] for k in ("spp", "mean_correlation", "max_onset_difference_bins")}
             for r in reversed(rows) if r["simulator"] == "mitsuba"), None),
        "runs": rows,
        "raw_embree": {"before": raw, "after": raw_after, "rays_per_second": raw_rate},
        "targets": {
            "error": TARGET_ERROR,
            "embree_seconds_to_error": t_embree, "embree_how": how_embree,
            "mitsuba_seconds_to_error": t_mitsuba, "mitsuba_how": how_mitsuba,
            "speedup": speedup, "speedup_ok": bool(speedup and speedup >= 2),
            "embree_rays_per_second": sim_rate,
            "embree_rays_per_second_largest_run": largest["rays_per_second"],
            "throughput_ratio": sim_rate / raw_rate,
            "throughput_ok": bool(sim_rate / raw_rate >= 0.5),
            "peak_rss_gb": peak_rss_gb(), "memory_ok": bool(peak_rss_gb() < 4.0),
        },
        "machine": {"cores": available_cores(), "platform": platform.platform(),
                    "python": sys.version.split()[0], "load_before": load_before,
                    "load_after": os.getloadavg()},
        "total_seconds": time.perf_counter() - t0,
    }

    table = Table(title=f"{scene.name}: {nx}x{ny} sensors, {scene.time.bins} bins, "
                        f"{threads} threads (error vs embree {reference_samples} samples)")
    for col in ("simulator", "setting", "seconds", "rel. L2 error", "rays or paths / s"):
        table.add_column(col, justify="right" if col != "simulator" else "left")
    for r in rows:
        rate = r.get("rays_per_second") or r.get("paths_per_second")
        table.add_row(r["simulator"], r["setting"], f"{r['seconds']:.2f}", f"{r['error']:.4f}",
                      f"{rate / 1e6:.1f} M")
    table.add_row("analytic", "patch 1 cm", f"{analytic['seconds']:.2f}",
                  f"{analytic['error']:.4f}", "")
    console.print(table)
    tg = result["targets"]
    summary = Table(title="targets")
    for col in ("target", "measured", "ok"):
        summary.add_column(col)

    def fmt(v: float | None, unit: str = "s") -> str:
        return "n/a" if v is None else f"{v:.2f} {unit}"

    summary.add_row("embree time to 3%", f"{fmt(t_embree)} ({how_embree})", "")
    summary.add_row("mitsuba time to 3%", f"{fmt(t_mitsuba)} ({how_mitsuba})", "")
    summary.add_row("speedup >= 2x", fmt(speedup, "x"), str(tg["speedup_ok"]))
    summary.add_row("embree sim / raw embreex >= 0.5",
                    f"{sim_rate / 1e6:.1f} / {raw_rate / 1e6:.1f} M rays/s = "
                    f"{tg['throughput_ratio']:.2f}", str(tg["throughput_ok"]))
    summary.add_row("peak memory < 4 GB", fmt(tg["peak_rss_gb"], "GB"), str(tg["memory_ok"]))
    summary.add_row("reference error (estimated)", f"{ref_error:.4f}", "")
    summary.add_row("analytic vs reference", f"error {analytic['error']:.4f}, energy "
                    f"{analytic['energy_ratio']:.4f}", "")
    agree = result["mitsuba_vs_reference_profiles"]
    if agree:
        summary.add_row(f"mitsuba ({agree['spp']} spp) vs reference profiles",
                        f"correlation {agree['mean_correlation']:.4f}, onsets within "
                        f"{agree['max_onset_difference_bins']} bins", "")
    console.print(summary)
    write_results(args.output, result, RESULT_KEYS)
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

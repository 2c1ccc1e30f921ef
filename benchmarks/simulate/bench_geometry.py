"""Benchmark of the hidden-geometry ray queries: ground-truth maps and the shadowing test.

For each thesis scene with its 64 x 64 wall: the time of
:func:`nlosfw.simulate.visibility.ground_truth_maps` (one +z ray per wall point, the
mesh built once, as ``simulate()`` does) and of
:func:`nlosfw.simulate.visibility.blocked_fraction` (the analytic simulator's
sight-line test, ~17 wall points x every surface sample). Best of ``--repeat``
wall-clock seconds; the first call (building the ray structure) is included in
every repeat, since each simulation builds it anew.

Both functions cast rays through trimesh, which uses Embree (embreex) when it is
installed and its own numpy code (with an rtree index) otherwise; ``--numpy``
forces the numpy code. Each run is stored under ``--label`` in
``benchmarks/results/bench_geometry.json`` (other labels are kept), so one file
holds, e.g., the timings before and after a change.

    python benchmarks/simulate/bench_geometry.py [--label after] [--numpy] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, best_of, write_results

from nlosfw.simulate import blocked_fraction, builtin_scene, ground_truth_maps, validate_scene

RESULTS = RESULTS_DIR / "bench_geometry.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'runs')
#: Keys written only by some modes.
OPTIONAL_KEYS = ('notes',)
SCENES = ("thesis_two_planes", "thesis_occluded", "thesis_planes", "thesis_concave")


def backend(force_numpy: bool) -> str:
    """Which ray code trimesh uses here (forcing its numpy code if asked)."""
    try:
        import trimesh.ray
    except ImportError:
        return "none"
    if force_numpy:
        trimesh.ray.has_embree = False     # what Trimesh() checks when it picks its ray code
    return "embree" if trimesh.ray.has_embree else "numpy"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", default="current", help="name of this run in the JSON")
    parser.add_argument("--numpy", action="store_true", help="force trimesh's numpy ray code")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)

    rays = backend(args.numpy)
    rows = []
    print(f"{'scene':<20} {'faces':>6} {'ground truth s':>15} {'blocked s':>10} "
          f"{'blocked':>8}  (rays: {rays}, best of {args.repeat})")
    for name in SCENES:
        scene = builtin_scene(name)
        geometry = validate_scene(scene)
        grid = scene.wall.grid_xyz()
        mesh = geometry.mesh
        gt_s, (depth, _) = best_of(lambda m=mesh, g=grid: ground_truth_maps(m, g),
                                   args.repeat)
        bf_s, blocked = best_of(lambda s=scene, m=mesh: blocked_fraction(s, m), args.repeat)
        row = {"scene": name, "wall": list(grid.shape[:2]), "faces": mesh.n_faces,
               "ground_truth_s": gt_s, "blocked_fraction_s": bf_s,
               "blocked_fraction": blocked, "hit_pixels": int(np.count_nonzero(depth > 0))}
        rows.append(row)
        print(f"{name:<20} {row['faces']:>6} {gt_s:>15.4f} {bf_s:>10.4f} {blocked:>8.4f}")

    results: dict[str, Any] = {"benchmark": "bench_geometry", "runs": {}}
    if RESULTS.exists():
        results = json.loads(RESULTS.read_text())
    results["runs"][args.label] = {
        "rays": rays,
        "repeat": args.repeat,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                    "numpy": np.__version__, "load_average": os.getloadavg()[0]},
        "scenes": rows,
    }
    write_results(RESULTS, results, RESULT_KEYS, OPTIONAL_KEYS)
    print(f"wrote {RESULTS} (run {args.label!r})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

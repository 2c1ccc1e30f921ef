"""Speed of ``rsd_prior``'s operator: one forward and one adjoint, the cost of a
FISTA iteration, on the size of a real-data fit at 16x.

The size is that of the shared diffuse S at 16x (a confocal 16 x 16 grid of kept points
5.08 cm apart, voxels every 1.27 cm on 62 x 61 columns, 84 depth planes, 32 frequencies,
complex64, kernel spectra cached as in a fit). ``workers`` 1 runs every plane on one
thread; -1 (the default) runs the planes on every core. Prints a table and writes
``benchmarks/results/bench_scene_operator.json``; ``--label`` names the code measured (run
it from another checkout for a baseline).

    python benchmarks/model/bench_scene_operator.py [--repeats 5] [--planes 84] [--label NAME]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, machine, write_results
from rich.console import Console
from rich.table import Table

from nlosfw.capture import CaptureGeometry, CaptureKind
from nlosfw.image import grid_layout
from nlosfw.model.physics import OperatorOptions, SceneOperator, VoxelLattice
from nlosfw.testing import fixtures

RESULTS = RESULTS_DIR / "bench_scene_operator.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'machine', 'runs')


def operator(planes: int, workers: int) -> SceneOperator:
    """The operator of a 16x fit of the diffuse S (see the module docstring)."""
    wall = grid_layout(fixtures.rect_wall_grid((16, 16), 0.0508))
    spacing = 0.0508 / 4
    lattice = VoxelLattice(np.linspace(0.235, 0.65, planes),
                           (wall.origin[0] - 2 * spacing, wall.origin[1] - 2 * spacing),
                           (spacing, spacing), (62, 61))
    geometry = CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=np.zeros(3),
                               sensor_xyz=np.zeros(3))
    freqs = np.linspace(6.0, 18.0, 32)
    return SceneOperator(lattice, wall, geometry, freqs,
                         OperatorOptions(dtype=np.complex64, workers=workers))


def time_iteration(op: SceneOperator, repeats: int) -> float:
    """The fastest of ``repeats`` forward + adjoint pairs (s), after one to fill the cache."""
    albedo = np.random.default_rng(0).random(op.lattice.volume_shape).astype(np.float32)
    op.adjoint(op.forward(albedo))
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        op.adjoint(op.forward(albedo))
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--planes", type=int, default=84)
    parser.add_argument("--label", default="this checkout")
    args = parser.parse_args()
    rows = {str(w): time_iteration(operator(args.planes, w), args.repeats) for w in (1, -1)}
    table = Table(title=f"rsd_prior operator, {args.planes} planes ({args.label})")
    table.add_column("workers")
    table.add_column("forward + adjoint (s)", justify="right")
    table.add_column("speed-up", justify="right")
    for workers, seconds in rows.items():
        table.add_row(workers, f"{seconds:.3f}", f"{rows['1'] / seconds:.2f}x")
    Console().print(table)
    previous = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    runs = previous.get("runs", {})
    runs[args.label] = {"seconds": rows, "planes": args.planes, "repeats": args.repeats}
    write_results(RESULTS, {
        "benchmark": "bench_scene_operator",
        "machine": machine(numpy=np.__version__),
        "runs": runs}, RESULT_KEYS, indent=1)


if __name__ == "__main__":
    main()

"""Speed of the neural volume's RSD operator in torch (issue 22): one forward and one
backward, the operator's share of a training step, on the size of a real-data fit at 16x.

The size is that of ``neural_volume_torch``'s fit of the shared diffuse S at 16x (a
confocal 16 x 16 grid of kept points 5.08 cm apart, voxels every 1.27 cm on 65 x 65
columns, 70 depth planes, all 135 frequencies of its band, complex64). The baseline, timed
in the same run on the same operator, is the batched product differentiated by autograd's
own ``bmm`` backward, which conjugates and transposes the spectra in every step; the
operator's backward computes S^H g as (g^H S)^H instead. Prints a table and writes
``benchmarks/results/bench_volume_operator.json``; needs the torch plugin.

    python benchmarks/bench_volume_operator.py [--repeats 3] [--planes 70] [--frequencies 135]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from nlosfw_torch.neural_volume import TorchPlaneOperator
from rich.console import Console
from rich.table import Table

from nlosfw.capture import CaptureGeometry, CaptureKind
from nlosfw.image import grid_layout
from nlosfw.model import OperatorOptions, SceneOperator, VoxelLattice, plane_stack
from nlosfw.testing import fixtures

RESULTS = Path(__file__).parent / "results" / "bench_volume_operator.json"


def operator(planes: int, frequencies: int) -> TorchPlaneOperator:
    """The torch operator of a 16x fit of the diffuse S (see the module docstring)."""
    wall = grid_layout(fixtures.rect_wall_grid((16, 16), 0.0508))
    spacing = 0.0508 / 4
    lattice = VoxelLattice(np.linspace(0.235, 0.65, planes),
                           (wall.origin[0] - spacing, wall.origin[1] - spacing),
                           (spacing, spacing), (65, 65))
    geometry = CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=np.zeros(3),
                               sensor_xyz=np.zeros(3))
    op = SceneOperator(lattice, wall, geometry, np.linspace(4.0, 20.0, frequencies),
                       OperatorOptions(dtype=np.complex64, cache_mb=0.0))
    return TorchPlaneOperator(plane_stack(op))


def autograd_bmm(op: TorchPlaneOperator) -> Callable[[torch.Tensor], torch.Tensor]:
    """The baseline: the operator's batched path with autograd's own ``bmm`` backward."""
    def forward(albedo: torch.Tensor) -> torch.Tensor:
        work = torch.zeros((albedo.shape[0],) + op.shape, dtype=op.dtype)
        work[(..., op.inputs[0], op.inputs[1])] = albedo.to(op.dtype)
        planes = torch.fft.fft2(work)
        columns = planes.permute(1, 2, 0).reshape(-1, planes.shape[0], 1)
        total = torch.bmm(op.spectra, columns).reshape(op.shape + (-1,)).permute(2, 0, 1)
        return torch.fft.ifft2(total)[(..., op.outputs[0], op.outputs[1])]
    return forward


def time_step(forward: Callable[[torch.Tensor], torch.Tensor], volume: tuple[int, ...],
              repeats: int) -> tuple[float, torch.Tensor]:
    """The fastest of ``repeats`` forward + backward passes (s), and the albedo's gradient."""
    albedo = torch.from_numpy(np.random.default_rng(0).random(volume).astype(np.float32))
    best, grad = float("inf"), torch.zeros(0)
    for _ in range(repeats + 1):                     # the first warms the allocator
        a = albedo.clone().requires_grad_(True)
        start = time.perf_counter()
        torch.sum(torch.abs(forward(a)) ** 2).backward()
        best = min(best, time.perf_counter() - start)
        grad = a.grad
    return best, grad


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--planes", type=int, default=70)
    parser.add_argument("--frequencies", type=int, default=135)
    args = parser.parse_args()
    op = operator(args.planes, args.frequencies)
    if not op.batched:
        raise SystemExit("the operator is not on the batched (CPU, confocal) path")
    volume = (args.planes, 65, 65)
    rows: dict[str, dict[str, float]] = {}
    before = torch.get_num_threads()
    for threads in sorted({1, before}):
        torch.set_num_threads(threads)
        baseline, expected = time_step(autograd_bmm(op), volume, args.repeats)
        seconds, grad = time_step(op, volume, args.repeats)
        mismatch = float(torch.linalg.norm(grad - expected) / torch.linalg.norm(expected))
        rows[str(threads)] = {"autograd_bmm_s": baseline, "operator_s": seconds,
                              "speedup": baseline / seconds, "gradient_mismatch": mismatch}
    torch.set_num_threads(before)
    table = Table(title=f"neural volume operator, {args.planes} planes x "
                        f"{args.frequencies} frequencies, forward + backward")
    for column in ("threads", "autograd bmm (s)", "operator (s)", "speed-up",
                   "gradient mismatch"):
        table.add_column(column, justify="right")
    for threads, row in rows.items():
        table.add_row(threads, f"{row['autograd_bmm_s']:.3f}", f"{row['operator_s']:.3f}",
                      f"{row['speedup']:.2f}x", f"{row['gradient_mismatch']:.1e}")
    Console().print(table)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({
        "benchmark": "bench_volume_operator",
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "python": platform.python_version(), "torch": torch.__version__},
        "planes": args.planes, "frequencies": args.frequencies, "repeats": args.repeats,
        "threads": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()

"""Speed of the neural volume's RSD operator in torch and JAX: one forward and
one backward, the operator's share of a training step, on the size of a real-data fit at
16x.

The size is that of ``neural_volume_*``'s fit of the shared diffuse S at 16x (a confocal
16 x 16 grid of kept points 5.08 cm apart, voxels every 1.27 cm on 65 x 65 columns
reaching two voxels past the kept points on each side, as ``rsd_prior`` plans them, 70
depth planes, all 135 frequencies of its band, complex64). Each backend's baseline is
timed in the same run on the same operator:

- torch: ``--torch-baseline autograd`` (the first change): the product per lattice point
  differentiated by autograd's own ``bmm`` backward, which multiplies by the spectra's
  conjugate transpose, against the operator's S^H g computed as (g^H S)^H, both per
  point; ``folded`` (the default, the second change): that product per point against one
  per orbit of the folded spectra (:func:`nlosfw.model.hybrid.fold_spectra`);
- JAX: the product summed over planes (the GPU's path); the operator on the CPU contracts
  the reordered spectra with an ``einsum`` instead. Both jitted, the spectra passed as
  arguments (closed over, XLA folds them into the program and compiles for minutes).

Prints a table and writes ``benchmarks/results/bench_volume_operator.json``; a backend
whose plugin is not installed is skipped.

    python benchmarks/model/bench_volume_operator.py [--repeats 3] [--planes 70] [--frequencies 135]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, machine, print_speedups, write_results

from nlosfw.capture import CaptureGeometry, CaptureKind
from nlosfw.image import grid_layout
from nlosfw.model.hybrid import PlaneStack, plane_stack
from nlosfw.model.physics import OperatorOptions, SceneOperator, VoxelLattice
from nlosfw.testing import fixtures

RESULTS = RESULTS_DIR / "bench_volume_operator.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('backends', 'benchmark', 'frequencies', 'machine', 'planes', 'repeats')


def stack_of(planes: int, frequencies: int) -> PlaneStack:
    """The operator constants of a 16x fit of the diffuse S (see the module docstring)."""
    wall = grid_layout(fixtures.rect_wall_grid((16, 16), 0.0508))
    spacing = 0.0508 / 4
    lattice = VoxelLattice(np.linspace(0.235, 0.65, planes),
                           (wall.origin[0] - 2 * spacing, wall.origin[1] - 2 * spacing),
                           (spacing, spacing), (65, 65))
    geometry = CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=np.zeros(3),
                               sensor_xyz=np.zeros(3))
    op = SceneOperator(lattice, wall, geometry, np.linspace(4.0, 20.0, frequencies),
                       OperatorOptions(dtype=np.complex64, cache_mb=0.0))
    return plane_stack(op)


def best_of(run: Callable[[], np.ndarray], repeats: int) -> tuple[float, np.ndarray]:
    """The fastest of ``repeats`` calls (s), after one that warms up (and compiles), and
    the last call's gradient."""
    grad = run()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        grad = run()
        best = min(best, time.perf_counter() - start)
    return best, grad


def torch_pair(stack: PlaneStack, albedo: np.ndarray, repeats: int, baseline_kind: str
               ) -> dict[str, float]:
    """torch, forward + backward: autograd's bmm backward against the operator's (per
    point), or the operator per point against the operator folded."""
    import torch
    from nlosfw_torch.neural_volume import TorchPlaneOperator

    op = TorchPlaneOperator(stack, fold=False)
    if baseline_kind == "folded":
        folded = TorchPlaneOperator(stack)
        if folded.folded is None:
            raise SystemExit("the stack's spectra do not fold: no folded product to time")

    def baseline(a: torch.Tensor) -> torch.Tensor:
        work = torch.zeros((a.shape[0],) + op.shape, dtype=op.dtype)
        work[(..., op.inputs[0], op.inputs[1])] = a.to(op.dtype)
        columns = torch.fft.fft2(work).permute(1, 2, 0).reshape(-1, a.shape[0], 1)
        total = torch.bmm(op.spectra, columns).reshape(op.shape + (-1,)).permute(2, 0, 1)
        return torch.fft.ifft2(total)[(..., op.outputs[0], op.outputs[1])]

    def gradient(forward: Callable[[torch.Tensor], torch.Tensor]) -> Callable[[], np.ndarray]:
        def run() -> np.ndarray:
            a = torch.from_numpy(albedo).requires_grad_(True)
            torch.sum(torch.abs(forward(a)) ** 2).backward()
            return a.grad.numpy()
        return run

    if baseline_kind == "folded":
        return _row(best_of(gradient(op), repeats), best_of(gradient(folded), repeats))
    return _row(best_of(gradient(baseline), repeats), best_of(gradient(op), repeats))


def jax_pair(stack: PlaneStack, albedo: np.ndarray, repeats: int) -> dict[str, float]:
    """JAX: the product summed over planes against the operator's einsum on the CPU."""
    import jax
    import jax.numpy as jnp
    from nlosfw_jax.neural_volume import JaxPlaneOperator

    op = JaxPlaneOperator(stack)
    if not op.batched:
        raise SystemExit("JAX's default device is not a CPU: the einsum path is not taken")
    plain = jax.device_put(stack.spectra)

    def baseline(a: Any, spectra: Any) -> Any:
        work = jnp.zeros((a.shape[0],) + stack.shape, spectra.dtype)
        work = work.at[(..., stack.inputs[0], stack.inputs[1])].set(a.astype(spectra.dtype))
        total = jnp.sum(spectra * jnp.fft.fft2(work)[:, None], axis=0)
        return jnp.fft.ifft2(total)[(..., stack.outputs[0], stack.outputs[1])]

    def gradient(forward: Callable[[Any, Any], Any], spectra: Any) -> Callable[[], np.ndarray]:
        grad = jax.jit(jax.grad(lambda a, s: jnp.sum(jnp.abs(forward(a, s)) ** 2)))
        return lambda: np.asarray(grad(jnp.asarray(albedo), spectra).block_until_ready())

    return _row(best_of(gradient(baseline, plain), repeats),
                best_of(gradient(lambda a, s: op.forward(a, s, None), op.spectra), repeats))


def _row(baseline: tuple[float, np.ndarray], operator: tuple[float, np.ndarray]
         ) -> dict[str, float]:
    mismatch = np.linalg.norm(operator[1] - baseline[1]) / np.linalg.norm(baseline[1])
    return {"baseline_s": baseline[0], "operator_s": operator[0],
            "speedup": baseline[0] / operator[0], "gradient_mismatch": float(mismatch)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--planes", type=int, default=70)
    parser.add_argument("--frequencies", type=int, default=135)
    parser.add_argument("--torch-baseline", choices=("folded", "autograd"), default="folded")
    args = parser.parse_args()
    stack = stack_of(args.planes, args.frequencies)
    albedo = np.random.default_rng(0).random((args.planes, 65, 65)).astype(np.float32)
    rows: dict[str, dict[str, Any]] = {}
    if importlib.util.find_spec("nlosfw_torch") is not None:
        rows["torch"] = torch_pair(stack, albedo, args.repeats, args.torch_baseline)
        rows["torch"]["baseline"] = args.torch_baseline
    if importlib.util.find_spec("nlosfw_jax") is not None:
        rows["jax"] = jax_pair(stack, albedo, args.repeats)
    print_speedups(f"neural volume operator, {args.planes} planes x {args.frequencies} "
                   f"frequencies, forward + backward ({os.cpu_count()} cores)", rows,
                   ("operator (s)", "operator_s"))
    write_results(RESULTS, {
        "benchmark": "bench_volume_operator",
        "machine": machine(),
        "planes": args.planes, "frequencies": args.frequencies, "repeats": args.repeats,
        "backends": rows}, RESULT_KEYS, indent=1)


if __name__ == "__main__":
    main()

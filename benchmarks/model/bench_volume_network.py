"""Speed of the neural volume's network pass on the CPU (every model of the
study within 120 s at 16x on 2 cores).

Each step of ``neural_volume_torch`` and ``neural_volume_jax`` evaluates the albedo's
network at every voxel and differentiates through it. Timed here, each against its
baseline in the same run: the forward and backward pass of the default network (SIREN,
64 x 64) over a lattice the size of the diffuse S's at 16x (70 x 65 x 65 = 295 750 voxels),
whole (every activation kept for the backward pass) against in pieces of ``CPU_CHUNK``
voxels, each run again in the backward pass (``volume_albedo(..., chunk)``), on one
thread (the neural volume's default). The gradient mismatch is the relative difference
of the parameters' gradients.

Prints a table and writes ``benchmarks/results/bench_volume_network.json``.

    python benchmarks/model/bench_volume_network.py [--repeats 5] [--threads 1]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import numpy as np
from harness import RESULTS_DIR, best_of, machine, print_speedups, write_results

from nlosfw.model.hybrid import volume_coordinates
from nlosfw.model.neural import FieldMode, FieldShape, NetworkBuild
from nlosfw.plugins import registered_network

RESULTS = RESULTS_DIR / "bench_volume_network.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'machine', 'network', 'repeats', 'rows', 'threads', 'voxels')
SHAPE = (70, 65, 65)


def _problem() -> tuple[np.ndarray, np.ndarray, np.ndarray, NetworkBuild, NetworkBuild]:
    coords = volume_coordinates(np.linspace(0.3, 1.2, SHAPE[0]), np.linspace(-1, 1, SHAPE[1]),
                                np.linspace(-1, 1, SHAPE[2]))
    rng = np.random.default_rng(0)
    gain = rng.uniform(0.5, 2.0, SHAPE).astype(np.float32)
    weights = rng.normal(size=SHAPE).astype(np.float32)
    builds = []
    for engine in ("torch", "jax"):
        network = registered_network("siren", engine)
        builds.append(NetworkBuild(network.network_factory, network.config_class(
            seed=0, hidden=[64, 64], device="cpu"), FieldShape(FieldMode.multi, SHAPE[1:],
                                                               SHAPE[0])))
    return coords, gain, weights, builds[0], builds[1]


def _row(whole: Callable[[], list[np.ndarray]], pieces: Callable[[], list[np.ndarray]],
         repeats: int) -> dict[str, float]:
    base, g_base = best_of(whole, repeats)
    new, g_new = best_of(pieces, repeats)
    mismatch = max(float(np.linalg.norm(a - b) / np.linalg.norm(b))
                   for a, b in zip(g_new, g_base, strict=True))
    return {"baseline_s": base, "new_s": new, "speedup": base / new,
            "gradient_mismatch": mismatch}


def torch_pass(repeats: int, threads: int) -> dict[str, float]:
    """torch: forward + backward, whole against in pieces."""
    import torch
    from nlosfw_torch.backend import TorchBackend
    from nlosfw_torch.neural_volume import CPU_CHUNK, volume_albedo

    coords, gain, weights, build, _ = _problem()
    engine = TorchBackend(build)
    state = {**engine.fixed, **engine.params}
    x, g, w = (torch.from_numpy(a) for a in (coords, gain, weights))

    def network(points: torch.Tensor) -> torch.Tensor:
        return torch.func.functional_call(engine.network, state, (points,))

    def grads(chunk: int | None) -> Callable[[], list[np.ndarray]]:
        def run() -> list[np.ndarray]:
            albedo = volume_albedo(network, x, g, -7.0, chunk)
            out = torch.autograd.grad(torch.sum(albedo * w), list(engine.params.values()))
            return [t.numpy() for t in out]
        return run

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return _row(grads(None), grads(CPU_CHUNK), repeats)
    finally:
        torch.set_num_threads(before)


def jax_pass(repeats: int) -> dict[str, float]:
    """JAX: jitted forward + backward, whole against in pieces (compiled before timing)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    from nlosfw_jax.backend import Fixed, JaxBackend
    from nlosfw_jax.neural_volume import CPU_CHUNK, volume_albedo

    coords, gain, weights, _, build = _problem()
    engine = JaxBackend(build)
    x, g, w = (jnp.asarray(a) for a in (coords, gain, weights))

    def grads(chunk: int | None) -> Callable[[], list[np.ndarray]]:
        def loss(params: object) -> jax.Array:
            network = eqx.combine(params, engine.rest,
                                  is_leaf=lambda n: isinstance(n, Fixed))
            return jnp.sum(volume_albedo(network, x, g, -7.0, chunk) * w)

        step = jax.jit(jax.grad(loss))

        def run() -> list[np.ndarray]:
            out = jax.block_until_ready(step(engine.params))
            return [np.asarray(a) for a in jax.tree.leaves(out)]
        run()                                               # compile
        return run

    return _row(grads(None), grads(CPU_CHUNK), repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1, help="torch's CPU threads")
    args = parser.parse_args()
    rows = {"torch": torch_pass(args.repeats, args.threads)}
    if importlib.util.find_spec("nlosfw_jax"):
        rows["jax"] = jax_pass(args.repeats)
    print_speedups(f"the neural volume's SIREN over {np.prod(SHAPE)} voxels, forward + "
                   f"backward ({os.cpu_count()} cores); baseline: the whole lattice at once",
                   rows, ("in pieces (s)", "new_s"))
    write_results(RESULTS, {
        "benchmark": "bench_volume_network",
        "machine": machine(),
        "voxels": int(np.prod(SHAPE)), "network": "siren 64 x 64", "threads": args.threads,
        "repeats": args.repeats, "rows": rows}, RESULT_KEYS, indent=1)


if __name__ == "__main__":
    main()

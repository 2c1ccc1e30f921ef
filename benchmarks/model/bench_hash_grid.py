"""Speed of ``hashgrid_torch``'s training on the CPU (every model of the study
within 120 s at 16x on 2 cores).

Two changes, each timed against its baseline in the same run:

- **the lookup** (the weighted sum of the 2^d corner rows per level, forward and
  backward): indexing the table and summing, differentiated by autograd (an accumulating
  ``index_put``), against the encoding's own function (``index_select`` and a batched
  product forward, one ``scatter_add`` per feature backward);
- **the corners** (which rows, with what weights): found for every batch, against found
  once per fit for the fixed training inputs and selected per batch. Timed as whole
  fits of the default network (``steps`` Adam steps, batches of 8192, one thread) on a
  field of a 16x fit's size (16 x 16 wall points, 135 frequencies, multi mode).

Prints a table and writes ``benchmarks/results/bench_hash_grid.json``.

    python benchmarks/model/bench_hash_grid.py [--steps 300] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the harness
import nlosfw_torch.networks as networks
import numpy as np
import torch
from harness import RESULTS_DIR, best_of, machine, write_results
from nlosfw_torch.hash_grid import HashGridEncoding, weighted_rows
from rich.console import Console
from rich.table import Table

from nlosfw.model.neural import FieldMode, FieldShape, HashGridFieldConfig, hash_grid_layout
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures

RESULTS = RESULTS_DIR / "bench_hash_grid.json"
#: The top-level keys of the results file (harness.write_results checks them).
RESULT_KEYS = ('benchmark', 'machine', 'repeats', 'rows', 'steps')


def lookup(repeats: int) -> dict[str, float]:
    """Forward + backward of one batch's lookup (8192 inputs, the default layout of a
    16 x 16 training grid), indexing against the encoding's function, on one thread."""
    layout = hash_grid_layout(HashGridFieldConfig(), FieldShape(FieldMode.multi, (16, 16),
                                                                135))
    corners = HashGridEncoding(layout).corners(torch.rand(8192, 3) * 2 - 1)
    table = torch.rand(int(sum(layout.table_sizes)), layout.features, requires_grad=True)
    grad = torch.rand(8192, len(layout.resolutions), layout.features)

    def indexing() -> torch.Tensor:
        out = (corners.weights[..., None] * table[corners.rows]).sum(-2)
        return torch.autograd.grad(out, table, grad)[0]

    def function() -> torch.Tensor:
        out = weighted_rows(table, corners.rows, corners.weights)
        return torch.autograd.grad(out, table, grad)[0]

    torch.set_num_threads(1)
    base, g_base = best_of(indexing, repeats)
    new, g_new = best_of(function, repeats)
    mismatch = float(torch.linalg.norm(g_new - g_base) / torch.linalg.norm(g_base))
    return {"baseline_ms": 1e3 * base, "new_ms": 1e3 * new, "speedup": base / new,
            "gradient_mismatch": mismatch}


def fits(steps: int, repeats: int) -> dict[str, float]:
    """Seconds per training step of ``hashgrid_torch`` at its defaults (``steps`` steps, no
    early stop), corners found per batch against found once."""
    field = fixtures.point_phasor_field((0.1, -0.05, 0.7), n=16,
                                        frequencies=np.linspace(4.0, 20.0, 135))
    options = {"steps": steps, "device": "cpu", "patience": 0}
    registry = load_plugins().registry
    cap = networks.CORNERS_MAX_BYTES

    def per_step(limit: int) -> float:
        networks.CORNERS_MAX_BYTES = limit
        try:
            model = registry.create("model", "hashgrid_torch", options)
            report = model.fit(field)
        finally:
            networks.CORNERS_MAX_BYTES = cap
        return float(report.history[-1]["seconds"]) / report.steps

    base = min(per_step(0) for _ in range(repeats))
    new = min(per_step(cap) for _ in range(repeats))
    return {"baseline_ms": 1e3 * base, "new_ms": 1e3 * new, "speedup": base / new}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rows = {"lookup, forward + backward": lookup(args.repeats),
            "training step (fit)": fits(args.steps, args.repeats)}
    table = Table(title=f"hashgrid_torch on the CPU ({os.cpu_count()} cores, one thread)")
    for column in ("what", "baseline (ms)", "new (ms)", "speed-up"):
        table.add_column(column, justify="right")
    for what, row in rows.items():
        table.add_row(what, f"{row['baseline_ms']:.1f}", f"{row['new_ms']:.1f}",
                      f"{row['speedup']:.2f}x")
    Console().print(table)
    write_results(RESULTS, {
        "benchmark": "bench_hash_grid",
        "machine": machine(torch=torch.__version__),
        "steps": args.steps, "repeats": args.repeats, "rows": rows}, RESULT_KEYS, indent=1)


if __name__ == "__main__":
    main()

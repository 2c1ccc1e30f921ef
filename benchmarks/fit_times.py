"""Fit times of field models on one measured capture, per device (issue 22: GPU times).

Each MODEL:DEVICE pair runs ``nlosfw.run`` on the capture at 16x (grid, count splitting,
thinning seed 0, ``stop_after=predict``) with ``model.device=DEVICE`` for the torch models,
and records ``timings.fit`` and the held-out excess error of metrics.json. Prints a table
and writes ``benchmarks/results/fit_times_<label>.json``.

    python benchmarks/fit_times.py CAPTURE.mat siren_torch:cuda,siren_torch:cpu --label h200
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one(capture: Path, model: str, device: str) -> dict[str, object]:
    """Fit seconds, wall seconds and held-out excess (dB) of one model on one device."""
    import nlosfw

    extra = [f"model.device={device}"] if model.endswith("_torch") else []
    start = time.perf_counter()
    out = nlosfw.run([f"capture.path={capture}", f"model={model}", "split.thinning=true",
                      "split.thinning_seed=0", "split.spatial_step=4", "sampling=grid",
                      "stop_after=predict", "figures.enabled=false", *extra],
                     output_dir=Path(tempfile.mkdtemp()) / "run")
    metrics = json.loads((out.dir / "metrics.json").read_text())
    heldout = metrics["field"]["model" if model != "interp" else "interp"]["splits"][
        "heldout_measurement"]
    return {"model": model, "device": device, "fit_seconds": metrics["timings"]["fit"],
            "wall_seconds": round(time.perf_counter() - start, 1),
            "excess_db": heldout["excess_db"], "floor_db": heldout["floor_db"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture", type=Path)
    parser.add_argument("pairs", help="MODEL:DEVICE[,MODEL:DEVICE ...]")
    parser.add_argument("--label", default="cpu", help="names the results file")
    args = parser.parse_args()
    if not args.capture.is_file():
        print(f"capture: {args.capture} is not a file")
        return 2
    os.environ.setdefault("NLOSFW_CACHE_DIR", tempfile.mkdtemp())
    rows = []
    print(f"{'model':22s} {'device':6s} {'fit s':>8s} {'wall s':>8s} {'excess dB':>10s}")
    for pair in args.pairs.split(","):
        model, _, device = pair.partition(":")
        row = one(args.capture.resolve(), model, device or "cpu")
        rows.append(row)
        print(f"{model:22s} {row['device']:6s} {row['fit_seconds']:8.1f} "
              f"{row['wall_seconds']:8.1f} {row['excess_db']:+10.2f}", flush=True)
    out = ROOT / "benchmarks" / "results" / f"fit_times_{args.label}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"capture": args.capture.name, "rows": rows}, indent=1) + "\n")
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

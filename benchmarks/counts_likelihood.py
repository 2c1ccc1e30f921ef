"""``rsd_prior`` fitted by the exact Poisson likelihood of the photon counts
(``likelihood: poisson_counts``) against its least-squares fit, on measured captures
(issue 22).

Each capture (a file, or every ``.mat`` of a folder) at each spatial step (``--steps``: 4
is 16x, 8 is 64x; grid, count splitting, ``split.spectral=none`` for both, since the
counts hold every frequency) and count-splitting seed runs ``nlosfw.run`` once per variant
(``--variants``: least squares and the counts' likelihood, default options), one run at a
time, and records the held-out excess error, the reconstruction's PSNR and
SSIM against half B's full scan, ``interp``'s, the fit's seconds and what it fitted.
Prints a table and writes ``benchmarks/results/counts_likelihood.json``.

    python benchmarks/counts_likelihood.py ../shared/data/real --steps 4,8 --seeds 0,1,2
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from timing import machine

ROOT = Path(__file__).resolve().parents[1]
#: What runs: a likelihood, then ``model.`` options after colons.
VARIANTS = "least_squares,poisson_counts"


def one(capture: Path, variant: str, step: int, seed: int) -> dict[str, object]:
    """The scores of one run of ``rsd_prior`` in ``variant`` (``VARIANTS``' form)."""
    import nlosfw

    likelihood, *options = variant.split(":")
    out = nlosfw.run([f"capture.path={capture}", "model=rsd_prior",
                      f"model.likelihood={likelihood}", *(f"model.{o}" for o in options),
                      "split.count_splitting=true",
                      f"split.count_splitting_seed={seed}", f"split.spatial_step={step}",
                      "sampling=grid", "split.spectral=none", "figures.enabled=false",
                      "reconstruction.single_frequency_images=0"],
                     output_dir=Path(tempfile.mkdtemp()) / "run")
    metrics = json.loads((out.dir / "metrics.json").read_text())
    sources = metrics["reconstruction"]["sources"]
    row: dict[str, object] = {
        "capture": capture.name, "step": step, "seed": seed, "variant": variant,
        "fit_seconds": metrics["timings"]["fit"],
        "fitted": metrics["field"]["model"]["fit"].get("fitted") or {}}
    for source in ("model", "interp"):
        heldout = metrics["field"][source]["splits"]["heldout_measurement"]
        row[f"{source}_excess_db"] = heldout["excess_db"]
        row[f"{source}_psnr"] = sources[source]["psnr"]
        row[f"{source}_ssim"] = sources[source]["ssim"]
    return row


def _table(rows: list[dict]) -> str:
    lines = ["| capture | sparsity | seed | variant | excess (dB) | interp | PSNR | interp "
             "| SSIM | interp | EM iterations | fit (s) |", "|" + "---|" * 12]
    for r in rows:
        its = r["fitted"].get("counts_iterations", "")
        lines.append(f"| {r['capture']} | {r['step'] ** 2}x | {r['seed']} | {r['variant']} "
                     f"| {r['model_excess_db']:.2f} | {r['interp_excess_db']:.2f} "
                     f"| {r['model_psnr']:.2f} | {r['interp_psnr']:.2f} "
                     f"| {r['model_ssim']:.3f} | {r['interp_ssim']:.3f} "
                     f"| {its if its == '' else int(its)} | {r['fit_seconds']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("captures", type=Path)
    parser.add_argument("--steps", default="4,8")
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--variants", default=VARIANTS,
                        help="comma-separated LIKELIHOOD[:OPTION=VALUE...] (model options)")
    parser.add_argument("--out", type=Path,
                        default=ROOT / "benchmarks" / "results" / "counts_likelihood.json")
    args = parser.parse_args(argv)
    files = (sorted(args.captures.glob("*.mat")) if args.captures.is_dir()
             else [args.captures])
    rows = []
    for capture in files:
        for step in (int(s) for s in args.steps.split(",")):
            for seed in (int(s) for s in args.seeds.split(",")):
                for variant in args.variants.split(","):
                    rows.append(one(capture, variant, step, seed))
                    sys.stdout.write(_table(rows[-1:]).splitlines()[-1] + "\n")
                    sys.stdout.flush()
    print(_table(rows))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "machine": machine(),
        "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Physics terms on measured captures: ``rsd_prior``'s optional terms and likelihoods
against its default least-squares fit, on the shared captures, by count splitting.

    python studies/physics_terms_measured/run.py run [--captures DIR] [--steps 4,8]
                                                     [--seeds 0,1,2] [--variants V,...]
    python studies/physics_terms_measured/run.py collect RUN_DIR [RUN_DIR ...]
    python studies/physics_terms_measured/run.py render

``run`` calls ``nlosfw.run`` once per capture (a file, or every ``.mat`` of a folder),
spatial step (4 is 16x, 8 is 64x; grid, count splitting, ``split.spectral=none`` for every
variant, since the counts' likelihood needs every frequency), count-splitting seed and
variant, one run at a time, each into ``--dir``/<n>. A variant is ``LIKELIHOOD[:OPTION=VALUE
...]`` (``model.`` options after colons): ``least_squares`` (the default fit),
``poisson_counts`` (the exact likelihood of the photon counts), ``poisson`` (its Gaussian
approximation), ``least_squares:lobe.fit=true`` (the reflectance lobe),
``least_squares:background=constant``. ``collect`` reads each run's metrics.json: the
held-out excess of the model and of ``interp``, their reconstruction PSNR and SSIM against
half B's full scan, the fit's seconds and what it fitted; ``render`` rewrites the page's
generated section and ``figure.svg`` from ``results.json``.

``run --calibration`` adds the calibration errors ``rsd_prior`` must survive, on simulated
captures (embree, Poisson noise, 16x): ``letter_t`` and ``thesis_two_planes`` with 0, 50 and
100 ps of timing jitter (``scene.noise.jitter_ps``), each scored against the full capture
with the same error; ``collect`` keeps those runs' ``raw``, ``interp`` and model scores.
``run --simulated judged,tuning`` adds ``rsd_prior`` on simulated sparse scans (16x and
64x): the judged scenes (``letter_t`` and ``thesis_two_planes`` noise-free with the
analytic simulator and with embree and Poisson noise, ``thesis_occluded`` with embree and
Poisson noise) and the tuning scenes (``thesis_planes`` and ``thesis_concave``, the same
two captures), scored and collected like the calibration cases.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: the shared helpers
import pages

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CAPTURES = ROOT.parent / "shared" / "data" / "real"
QUESTION = ("Do `rsd_prior`'s terms for real systems (background, response, reflectance "
            "lobe) and the photon counts' likelihood predict measured captures better than "
            "its least-squares fit?")
FIGURE = "figure.svg"
VARIANTS = "least_squares,poisson_counts"
#: The calibration cases ``run --calibration`` runs: scenes and timing jitters (ps).
CALIBRATION_SCENES = ("letter_t", "thesis_two_planes")
CALIBRATION_JITTERS = (0, 50, 100)
#: The simulated sparse scans ``run --simulated`` runs, per group: (scene, simulator,
#: noise model) at spatial steps 4 and 8 (16x and 64x).
SIMULATED = {
    "judged": [(scene, simulator, noise) for scene in ("letter_t", "thesis_two_planes")
               for simulator, noise in (("analytic", "none"), ("embree", "poisson"))]
    + [("thesis_occluded", "embree", "poisson")],
    "tuning": [(scene, simulator, noise) for scene in ("thesis_planes", "thesis_concave")
               for simulator, noise in (("analytic", "none"), ("embree", "poisson"))],
}
SIMULATED_STEPS = (4, 8)
SCORES = ("psnr", "ssim", "volume_psnr", "volume_ssim", "depth_rmse_m")
SHORT = {"data_diffuse_s.mat": "diffuse S", "data_dot_chart_40cm.mat": "dot chart",
         "data_resolution_chart_40cm.mat": "resolution chart"}


def main(argv: Sequence[str] | None = None) -> int:
    return pages.main(pages.Study(HERE, run, collect, render, _arguments,
                                  description=__doc__.split("\n\n")[0]), argv)


def _arguments(run_parser: argparse.ArgumentParser,
               collect_parser: argparse.ArgumentParser) -> None:
    run_parser.add_argument("--captures", type=Path, default=CAPTURES,
                            help="a capture file or a folder of .mat captures")
    run_parser.add_argument("--steps", default="4,8", help="spatial steps (4: 16x, 8: 64x)")
    run_parser.add_argument("--seeds", default="0,1,2", help="count-splitting seeds")
    run_parser.add_argument("--variants", default=VARIANTS,
                            help="comma-separated LIKELIHOOD[:OPTION=VALUE...] (model options)")
    run_parser.add_argument("--dir", type=Path, default=ROOT / "multirun" / "physics_terms",
                            help="the runs go to DIR/<n>")
    run_parser.add_argument("--calibration", action="store_true",
                            help="also the simulated calibration cases (timing jitter)")
    run_parser.add_argument("--simulated", default="",
                            help=f"also simulated sparse scans, comma-separated groups: "
                                 f"{', '.join(SIMULATED)}")
    collect_parser.add_argument("dirs", type=Path, nargs="+", help="run directories")
    for parser in (run_parser, collect_parser):
        parser.add_argument("--out", type=Path, default=None,
                            help="write the results here instead of results.json")


def overrides(capture: Path, variant: str, step: int, seed: int) -> list[str]:
    """The ``nlosfw.run`` overrides of one run of ``rsd_prior`` in ``variant``."""
    likelihood, *options = variant.split(":")
    return [f"capture.path={capture}", "model=rsd_prior", f"model.likelihood={likelihood}",
            *(f"model.{o}" for o in options), "split.count_splitting=true",
            f"split.count_splitting_seed={seed}", f"split.spatial_step={step}",
            "sampling=grid", "split.spectral=none", "figures.enabled=false",
            "reconstruction.single_frequency_images=0"]


def run(args: argparse.Namespace) -> None:
    """Every run, one at a time, through ``nlosfw.run`` (then ``collect`` reads them)."""
    from nlosfw import run as run_nlosfw

    files = (sorted(args.captures.glob("*.mat")) if args.captures.is_dir()
             else [args.captures])
    args.dirs = []
    for capture in files:
        for step in (int(s) for s in args.steps.split(",")):
            for seed in (int(s) for s in args.seeds.split(",")):
                for variant in args.variants.split(","):
                    out = args.dir / str(len(args.dirs))
                    given = overrides(capture.resolve(), variant, step, seed)
                    print(f"$ nlosfw.run {' '.join(given)}", flush=True)
                    run_nlosfw(given, output_dir=out)
                    args.dirs.append(out)
    for given in simulated_overrides(args.calibration, args.simulated):
        out = args.dir / str(len(args.dirs))
        print(f"$ nlosfw.run {' '.join(given)}", flush=True)
        run_nlosfw(given, output_dir=out)
        args.dirs.append(out)


def simulated_overrides(calibration: bool, groups: str) -> list[list[str]]:
    """The ``nlosfw.run`` overrides of the simulated runs: the calibration cases (timing
    jitter, 16x), then each of ``groups``' (comma-separated :data:`SIMULATED` names) cases
    at 16x and 64x."""
    unknown = sorted({g for g in groups.split(",") if g} - set(SIMULATED))
    if unknown:
        raise SystemExit(f"--simulated: unknown group(s) {', '.join(unknown)}; valid: "
                         f"{', '.join(SIMULATED)}")
    every = ["model=rsd_prior", "figures.enabled=false",
             "reconstruction.single_frequency_images=0"]
    runs = [[f"scene={scene}", "simulator=embree", "scene.noise.model=poisson",
             f"scene.noise.jitter_ps={jitter}", "split.spatial_step=4", *every]
            for scene in (CALIBRATION_SCENES if calibration else ())
            for jitter in CALIBRATION_JITTERS]
    for group in (g for g in groups.split(",") if g):
        runs += [[f"scene={scene}", f"simulator={simulator}", f"scene.noise.model={noise}",
                  f"split.spatial_step={step}", *every]
                 for scene, simulator, noise in SIMULATED[group] for step in SIMULATED_STEPS]
    return runs


def calibration_row(metrics: dict[str, Any], given: dict[str, str]) -> dict[str, Any]:
    """A simulated run's row: its case, its step and each source's scores."""
    jitter = float(given.get("scene.noise.jitter_ps", 0))
    case = "/".join([given.get("scene", "?"), str(metrics["run"].get("simulator") or "?"),
                     given.get("scene.noise.model", "none")]) + (
        f"/jitter{jitter:g}ps" if jitter else "")
    sources = metrics["reconstruction"]["sources"]
    return {"case": case, "step": int(given.get("split.spatial_step", 4)),
            "scores": {name: {k: sources[source].get(k) for k in SCORES}
                       for name, source in (("raw", "raw"), ("interp", "interp"),
                                            ("rsd_prior", "model"))}}


def one(run_dir: Path) -> dict[str, Any]:
    """One run's row: what ran (its overrides) and the scores its metrics.json recorded."""
    from nlosfw.report import read_run

    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    given = dict(o.split("=", 1) for o in read_run(run_dir, run_dir.parent).overrides
                 if "=" in o)
    if "capture.path" not in given:
        return calibration_row(metrics, given)
    options = [f"{k[len('model.'):]}={v}" for k, v in given.items()
               if k.startswith("model.") and k != "model.likelihood"]
    sources = metrics["reconstruction"]["sources"]
    row: dict[str, Any] = {
        "capture": Path(given["capture.path"]).name,
        "step": int(given["split.spatial_step"]),
        "seed": int(given["split.count_splitting_seed"]),
        "variant": ":".join([given.get("model.likelihood", "least_squares"), *options]),
        "fit_seconds": metrics["timings"]["fit"],
        "fitted": metrics["field"]["model"]["fit"].get("fitted") or {}}
    for source in ("model", "interp"):
        heldout = metrics["field"][source]["splits"]["heldout_measurement"]
        row[f"{source}_excess_db"] = heldout["excess_db"]
        row[f"{source}_psnr"] = sources[source]["psnr"]
        row[f"{source}_ssim"] = sources[source]["ssim"]
    return row


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """The study's rows, one per run directory; prints the page's generated section."""
    found = [one(d) for d in args.dirs]
    results = {"question": QUESTION, "source": "the runs' metrics.json, read by `run.py collect`",
               "recorded": pages.recorded(), "rows": [r for r in found if "case" not in r],
               "calibration": {"recorded": pages.recorded(), "source": "the runs of "
                               "`run --calibration`", "cases": [r for r in found if "case" in r]}}
    print(results_markdown(results))
    return results


# ---------------------------------------------------------------------- the page
def _cells(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, int], dict[str, list[dict]]]:
    """Rows grouped by (capture, step), then by variant (in the order they ran)."""
    cells: dict[tuple[str, int], dict[str, list[dict]]] = {}
    for r in rows:
        cells.setdefault((r["capture"], r["step"]), {}).setdefault(r["variant"], []).append(r)
    return cells


def _mean(rows: Sequence[dict[str, Any]], key: str) -> float:
    return statistics.fmean(float(r[key]) for r in rows)


def _span(values: Sequence[int]) -> str:
    return "-" if not values else (f"{min(values)}" if min(values) == max(values)
                                   else f"{min(values)}–{max(values)}")


def summary_table(rows: Sequence[dict[str, Any]]) -> str:
    """Per capture and sparsity, each variant's mean over seeds (``a / b`` for two)."""
    cells = _cells(rows)
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    shown = " / ".join(variants)
    lines = [f"| capture | sparsity | seeds | held-out excess (dB): {shown} | PSNR (dB) | SSIM "
             "| interp: excess / PSNR / SSIM | EM iterations | fit (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for (capture, step), by in cells.items():
        runs = [by[v] for v in variants if v in by]
        seeds = sorted({r["seed"] for group in runs for r in group})
        its = [int(r["fitted"]["counts_iterations"]) for group in runs for r in group
               if "counts_iterations" in r["fitted"]]
        every = [r for group in runs for r in group]

        def each(key: str, digits: int, groups: list[list[dict]] = runs) -> str:
            return " / ".join(f"{_mean(g, key):.{digits}f}" for g in groups)

        lines.append(
            f"| {SHORT.get(capture, capture)} | {step * step}× | "
            f"{' '.join(str(s) for s in seeds)} | {each('model_excess_db', 2)} | "
            f"{each('model_psnr', 2)} | {each('model_ssim', 3)} | "
            f"{each('interp_excess_db', 2, [every])} / {each('interp_psnr', 2, [every])} / "
            f"{each('interp_ssim', 3, [every])} | {_span(its)} | {each('fit_seconds', 0)} |")
    return "\n".join(lines)


def calibration_table(calibration: dict[str, Any]) -> list[str]:
    """The simulated cases: each source's PSNR / SSIM (front view) and ``rsd_prior``'s
    depth RMSE, at the case's sparsity."""
    lines = ["| case | sparsity | raw: PSNR / SSIM | interp | rsd_prior | "
             "rsd_prior depth RMSE (mm) |", "|---|---|---|---|---|---|"]
    for case in calibration["cases"]:
        s = case["scores"]
        cells = [f"{s[n]['psnr']:.1f} / {s[n]['ssim']:.3f}" for n in ("raw", "interp",
                                                                       "rsd_prior")]
        depth = s["rsd_prior"].get("depth_rmse_m")
        lines.append(f"| {case['case']} | {case['step'] ** 2}× | {' | '.join(cells)} | "
                     f"{'-' if depth is None else f'{1000 * depth:.1f}'} |")
    return lines


def results_markdown(results: dict[str, Any]) -> str:
    """The page's generated section, from the collected runs."""
    rows = results["rows"]
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    return "\n".join([
        "Generated by `python studies/physics_terms_measured/run.py render` from "
        f"`results.json`: {len(rows)} runs of `rsd_prior` (variants: "
        f"{', '.join(f'`{v}`' for v in variants)}; grid, count splitting, "
        "`split.spectral=none`). " + pages.recorded_line(results),
        "",
        "Each variant's mean over the count-splitting seeds, in the order listed (`a / b`); "
        "`interp` is the same in every run of a cell. The held-out excess is lower-better.",
        "",
        summary_table(rows),
        "",
        "**Simulated captures** (`run --calibration`: calibration errors, embree, Poisson "
        "noise, 16×; `run --simulated judged,tuning`: sparse scans at 16× and 64×; each "
        "source scored against the full capture with the same error). "
        + pages.recorded_line(results["calibration"]),
        "",
        *calibration_table(results["calibration"]),
        "",
        f"![held-out excess of each variant per capture and sparsity]({FIGURE})",
    ]) + "\n"


def render(results: dict[str, Any], folder: Path) -> None:
    """The page's generated section and ``figure.svg``, from ``results``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pages.replace_generated(folder / "README.md", results_markdown(results))
    rows = results["rows"]
    cells = _cells(rows)
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    labels = [f"{SHORT.get(c, c)}\n{s * s}×" for c, s in cells]
    with matplotlib.rc_context(pages.plain_figure_settings()):
        fig, ax = plt.subplots(figsize=(9, 3.4))
        width = 0.8 / (len(variants) + 1)
        for k, variant in enumerate(variants):
            ax.bar([i + k * width for i in range(len(cells))],
                   [_mean(by[variant], "model_excess_db") if variant in by else 0.0
                    for by in cells.values()], width, label=variant)
        ax.bar([i + len(variants) * width for i in range(len(cells))],
               [_mean([r for g in by.values() for r in g], "interp_excess_db")
                for by in cells.values()], width, label="interp", color="0.6")
        ax.set_xticks([i + 0.4 - width / 2 for i in range(len(cells))], labels, fontsize=8)
        ax.set_ylabel("held-out excess (dB)")
        ax.axhline(0.0, color="k", linewidth=0.5)
        ax.legend(fontsize=8)
        fig.tight_layout()
        pages.save_figure(fig, folder / FIGURE)
        plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())

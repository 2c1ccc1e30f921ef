"""Thesis reproduction: the default run and the thesis presets (figs. 4.2-5.5) at full
size, the neural field's held-out error against interpolation's.

    python studies/thesis_reproduction/run.py run [--dir DIR] [OVERRIDE ...]
    python studies/thesis_reproduction/run.py collect DIR
    python studies/thesis_reproduction/run.py render

``run`` runs the default experiment (``python -m nlosfw`` into ``DIR/default``) and the
sweep of every thesis figure preset (``python -m nlosfw -cn reproduce -m`` into
``DIR/presets``; ``python -m nlosfw report DIR/presets`` then sets our numbers beside the
thesis's published ones), then collects them. ``collect`` reads each run's metrics.json:
per field source (the preset's model, the models it compares, ``interp``) its plugin,
parameter count and held-out NMSE (held-out pixels where the split holds pixels out,
else held-out frequencies); for the default run also the held-out frequencies' NMSE and the
reconstructions' PSNR and SSIM. ``render`` rewrites the page's generated section and
``figure.svg``.

``run --field-models`` also runs the field models on the thesis split of
``thesis_two_planes`` (analytic simulator, every other wall sample, a tenth of the
frequencies held out interleaved), noise-free and with Poisson noise, through
``nlosfw.run`` into ``DIR/field_models/<n>``; ``collect`` reads each run's held-out relative
L2 errors (and, noisy, the error of the whole prediction against the noise-free field). A
``collect`` without those runs keeps the section the previous ``results.json`` holds.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: the shared helpers
import pages

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
QUESTION = ("Does nlosfw reproduce the thesis's neural-field experiments, and does the "
            "neural field beat interpolation on held-out samples?")
FIGURE = "figure.svg"
#: What each preset reproduces, in the thesis's order.
PRESETS = {
    "thesis_fig4_2": "fig. 4.2, one frequency",
    "thesis_fig4_3": "fig. 4.3, held-out frequencies at 64 × 64",
    "thesis_fig4_4": "fig. 4.4, 32 → 64 and held-out frequencies",
    "thesis_fig5_1": "fig. 5.1 `thesis_planes`",
    "thesis_fig5_3": "fig. 5.3 `thesis_concave`",
    "thesis_fig5_4": "fig. 5.4 `thesis_two_planes` (embree)",
    "thesis_fig5_5": "fig. 5.5 `thesis_occluded`",
}
#: ``run --field-models``: the models and the two captures (the noisy one's scene overrides).
FIELD_MODELS = (["model=interp"], ["model=interp", "model.demodulate=false"],
                *([f"model={name}"] for name in ("siren_torch", "siren_jax", "pe_torch", "pe_jax",
                                                 "tanh_torch", "tanh_jax")))
FIELD_VARIANTS = {"clean": ["scene.noise.model=none"],
                  "noisy": ["scene.noise.model=poisson", "scene.noise.photons=1000000"]}
#: The held-out sets of the field models' table, in its order.
FIELD_SETS = ("heldout_pixels", "heldout_pixels_inside", "heldout_frequencies", "all")


def main(argv: Sequence[str] | None = None) -> int:
    return pages.main(pages.Study(HERE, run, collect, render, _arguments,
                                  description=__doc__.split("\n\n")[0]), argv)


def _arguments(run_parser: argparse.ArgumentParser,
               collect_parser: argparse.ArgumentParser) -> None:
    run_parser.add_argument("--dir", type=Path, default=None,
                            help="runs go to DIR/default and DIR/presets "
                                 "(default: multirun/thesis-<date>)")
    run_parser.add_argument("--field-models", action="store_true",
                            help="also the field models on the thesis split (DIR/field_models)")
    run_parser.add_argument("overrides", nargs="*", help="Hydra overrides for every run")
    collect_parser.add_argument("dir", type=Path, help="the folder `run` wrote")
    for parser in (run_parser, collect_parser):
        parser.add_argument("--out", type=Path, default=None,
                            help="write the results here instead of results.json")


def run(args: argparse.Namespace) -> None:
    """The default run, the presets' sweep and its report (then ``collect`` reads them)."""
    root = (args.dir or ROOT / "multirun" / f"thesis-{time.strftime('%Y%m%d-%H%M%S')}"
            ).resolve()
    nlosfw = [sys.executable, "-m", "nlosfw"]
    for command in ([*nlosfw, f"hydra.run.dir={root / 'default'}", *args.overrides],
                    [*nlosfw, "-cn", "reproduce", "-m", f"hydra.sweep.dir={root / 'presets'}",
                     *args.overrides],
                    [*nlosfw, "report", str(root / "presets")]):
        print("$ " + shlex.join(command), flush=True)
        subprocess.run(command, check=True, cwd=ROOT)
    if args.field_models:
        run_field_models(root / "field_models", args.overrides)
    args.dir = root


def field_model_overrides(variant: str, model: Sequence[str]) -> list[str]:
    """The ``nlosfw.run`` overrides of one field model (its ``model`` overrides) on the
    thesis split of one capture."""
    return ["scene=thesis_two_planes", "simulator=analytic", *FIELD_VARIANTS[variant],
            "split.spatial_step=2", "split.spectral=interleaved", *model,
            "figures.enabled=false", "reconstruction.single_frequency_images=0"]


def run_field_models(folder: Path, overrides: Sequence[str]) -> None:
    """Every field model on both captures, one run at a time, into ``folder/<n>``."""
    from nlosfw import run as run_nlosfw

    n = 0
    for variant in FIELD_VARIANTS:
        for model in FIELD_MODELS:
            given = [*field_model_overrides(variant, model), *overrides]
            print(f"$ nlosfw.run {' '.join(given)}", flush=True)
            run_nlosfw(given, output_dir=folder / str(n))
            n += 1


def collect_field_models(folder: Path) -> dict[str, Any]:
    """The field models' section from the runs under ``folder``: per capture and model, the
    held-out relative L2 errors its metrics.json recorded (against the captured field) and,
    noisy, its whole prediction's against the noise-free field."""
    from nlosfw.report import read_run

    variants: dict[str, dict[str, Any]] = {}
    for run_dir in sorted((p.parent for p in folder.rglob("metrics.json")),
                          key=lambda p: int(p.name) if p.name.isdigit() else 0):
        given = dict(o.split("=", 1) for o in read_run(run_dir, folder).overrides if "=" in o)
        entry = _metrics(run_dir)["field"]["model"]
        splits = entry.get("splits") or {}
        variant = "noisy" if given.get("scene.noise.model") == "poisson" else "clean"
        options = " ".join(f"{k[len('model.'):]}={v}" for k, v in given.items()
                           if k.startswith("model.") and k != "model.seed")
        name = entry.get("plugin", given.get("model", "?"))
        variants.setdefault(variant, {"models": []})["models"].append({
            "model": f"{name} [{options}]" if options else name,
            "errors": {k: (splits.get(k) or {}).get("relative_l2") for k in FIELD_SETS},
            "denoised": (entry.get("denoising") or {}).get("relative_l2")})
    return {"recorded": pages.recorded(), "source": "the runs of `run --field-models`: "
            "held-out errors against the captured field", "scene": "thesis_two_planes",
            "simulator": "analytic", "variants": variants}


def _heldout(entry: dict[str, Any]) -> tuple[str, float | None]:
    """The held-out split a field source is judged on and its NMSE (dB)."""
    splits = entry.get("splits") or {}
    for split in ("heldout_pixels", "heldout_frequencies"):
        if (splits.get(split) or {}).get("nmse_db") is not None:
            return split, splits[split]["nmse_db"]
    return "none", None


def _metrics(run_dir: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    return data


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """The default run's and the presets' scores; prints the page's generated section."""
    from nlosfw.report import read_run

    default = _metrics(args.dir / "default")
    sources = default["reconstruction"]["sources"]
    default_rows = []
    for source in ("model", "interp", "raw"):
        entry = default["field"].get(source) or {}
        splits = entry.get("splits") or {}
        default_rows.append({
            "field": entry.get("plugin", source) if source != "raw" else "raw",
            "n_parameters": entry.get("n_parameters"),
            "heldout_pixels_db": (splits.get("heldout_pixels") or {}).get("nmse_db"),
            "heldout_frequencies_db": (splits.get("heldout_frequencies") or {}).get("nmse_db"),
            "psnr": sources[source]["psnr"], "ssim": sources[source]["ssim"]})
    presets = []
    sweep = args.dir / "presets"
    for run_dir in sorted(p.parent for p in sweep.rglob("metrics.json")):
        given = dict(o.split("=", 1) for o in read_run(run_dir, sweep).overrides if "=" in o)
        metrics = _metrics(run_dir)
        interp = _heldout(metrics["field"].get("interp") or {})[1]
        for source, entry in metrics["field"].items():
            if source == "interp":
                continue
            split, value = _heldout(entry)
            presets.append({"preset": given.get("experiment", "?"), "source": source,
                            "network": entry.get("plugin", source),
                            "n_parameters": entry.get("n_parameters"), "split": split,
                            "nmse_db": value, "interp_db": interp, "note": ""})
    fields = args.dir / "field_models"
    results = {"question": QUESTION, "source": "the runs' metrics.json, read by `run.py collect`",
               "recorded": pages.recorded(), "default_run": default_rows, "presets": presets,
               "field_models": (collect_field_models(fields) if fields.is_dir() else
                                pages.read_results(HERE).get("field_models"))}
    print(results_markdown(results))
    return results


# ---------------------------------------------------------------------- the page
def _db(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f} dB".replace("-", "−")


def field_models_markdown(section: dict[str, Any] | None) -> list[str]:
    """The field models on the thesis split: each model's held-out relative L2 errors,
    noise-free / noisy."""
    if not section:
        return ["**Field models on the thesis split**: not run (`run --field-models`)."]
    variants = [v for v in ("clean", "noisy") if v in section["variants"]]
    models: dict[str, dict[str, dict[str, Any]]] = {}
    for variant in variants:
        for row in section["variants"][variant]["models"]:
            models.setdefault(row["model"], {})[variant] = row["errors"]

    def cell(model: str, key: str) -> str:
        values = [models[model].get(v, {}).get(key) for v in variants]
        return " / ".join("—" if x is None else f"{x:.3f}" for x in values)

    lines = ["| model | " + " | ".join(k.replace("_", " ") for k in FIELD_SETS) + " |",
             "|---|" + "---|" * len(FIELD_SETS)]
    lines += [f"| `{m}` | " + " | ".join(cell(m, k) for k in FIELD_SETS) + " |"
              for m in models]
    return [f"**Field models on the thesis split** (`{section['scene']}`, "
            f"{section['simulator']} simulator; every other wall sample, a tenth of the "
            f"frequencies held out): relative L2 error, {' / '.join(variants)}. "
            + pages.recorded_line(section), "", *lines]


def results_markdown(results: dict[str, Any]) -> str:
    """The page's generated section, from the collected runs."""
    default = ["| field | parameters | held-out pixels | held-out frequencies "
               "| reconstruction PSNR / SSIM |", "|---|---|---|---|---|"]
    for r in results["default_run"]:
        default.append(f"| `{r['field']}` | {r['n_parameters'] or '—'} | "
                       f"{_db(r['heldout_pixels_db'])} | {_db(r['heldout_frequencies_db'])} | "
                       f"{r['psnr']:.1f} dB / {r['ssim']:.3f} |")
    presets = ["| preset | network | parameters | held-out split | ours | `interp` |",
               "|---|---|---|---|---|---|"]
    order = {name: k for k, name in enumerate(PRESETS)}
    for r in sorted(results["presets"], key=lambda r: order.get(r["preset"], len(order))):
        note = f" ({r['note']})" if r["note"] else ""
        presets.append(f"| {PRESETS.get(r['preset'], r['preset'])} | {r['network']} | "
                       f"{r['n_parameters']} | {r['split'].replace('_', ' ')} | "
                       f"{_db(r['nmse_db'])}{note} | {_db(r['interp_db'])} |")
    return "\n".join([
        "Generated by `python studies/thesis_reproduction/run.py render` from `results.json`. "
        + pages.recorded_line(results),
        "",
        "**The default run** (`python -m nlosfw`): NMSE of the complex field against the "
        "true 64 × 64 field; PSNR and SSIM of the front view against the full capture's.",
        "",
        *default,
        "",
        "**The thesis presets at full size** (`python -m nlosfw -cn reproduce -m`): held-out "
        "NMSE, thesis architectures trained with our recipe.",
        "",
        *presets,
        "",
        *field_models_markdown(results.get("field_models")),
        "",
        f"![held-out NMSE of each preset's network against interp]({FIGURE})",
    ]) + "\n"


def render(results: dict[str, Any], folder: Path) -> None:
    """The page's generated section and ``figure.svg``, from ``results``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pages.replace_generated(folder / "README.md", results_markdown(results))
    order = {name: k for k, name in enumerate(PRESETS)}
    rows = sorted(results["presets"], key=lambda r: order.get(r["preset"], len(order)))
    labels = [f"{r['preset'].removeprefix('thesis_')}\n{r['network']}" for r in rows]
    with matplotlib.rc_context(pages.plain_figure_settings()):
        fig, ax = plt.subplots(figsize=(10, 3.4))
        xs = range(len(rows))
        ax.bar([x - 0.2 for x in xs], [r["nmse_db"] for r in rows], 0.4, label="ours")
        ax.bar([x + 0.2 for x in xs], [r["interp_db"] for r in rows], 0.4, label="interp",
               color="0.6")
        ax.set_xticks(list(xs), labels, fontsize=7)
        ax.set_ylabel("held-out NMSE (dB)")
        ax.axhline(0.0, color="k", linewidth=0.5)
        ax.legend(fontsize=8)
        fig.tight_layout()
        pages.save_figure(fig, folder / FIGURE)
        plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())

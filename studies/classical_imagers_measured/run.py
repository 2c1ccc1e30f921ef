"""Classical imagers on the Stanford captures: nlosfw's ``lct``, ``fk``, ``fbp`` and ``fft``
against the authors' LCT on the shared measured captures.

    python studies/classical_imagers_measured/run.py run [--captures DIR] [--only NAME ...]
                                                         [--dir DIR] [OVERRIDE ...]
    python studies/classical_imagers_measured/run.py collect SWEEP_DIR [SWEEP_DIR ...]
    python studies/classical_imagers_measured/run.py render

``run`` images each capture with the four imagers at their defaults in one Hydra sweep
(``python -m nlosfw -m capture.path=FILE model=none output.keep=[reconstructions]
imager=lct,fk,fbp,fft``, into ``DIR/<stem>``: the capture as its format reads it, the
automatic depths; ``lct``, ``fk`` and ``fbp`` over the measured-capture band, ``fft`` over
the default transform's), then collects them. ``collect`` reads each run's volume
(``nlosfw.image.read_reconstruction``) and compares it with the authors' LCT
(``tests/image/lct_reference.py``: their MATLAB procedure, per-scene falloff, SNR and depth
window; 8 ps bins): ``ncc``, the normalised cross-correlation (``nlosfw.evaluation.ncc``)
of the front views (the amplitude's maximum over depth; theirs the maximum over their
window of max(real, 0)), and ``depth_error_m``, the depth of the volume's brightest voxel
minus theirs. ``render`` rewrites the page's generated section and ``figure.svg``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/image/lct_reference.py
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # studies/: the shared helpers
import pages

from nlosfw.common import override_value
from nlosfw.evaluation import amplitude, ncc
from nlosfw.image import read_reconstruction

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CAPTURES = Path(os.environ.get("NLOSFW_REAL_DATA") or ROOT.parent / "shared" / "data" / "real")
QUESTION = ("Do nlosfw's classical imagers (`lct`, `fk`, `fbp`) and its phasor-field `fft` "
            "imager reproduce the authors' LCT images of the Stanford captures?")
IMAGERS = ("lct", "fk", "fbp", "fft")
FIGURE = "figure.svg"
#: The targets every imager must meet on every capture.
TARGETS = {"ncc": 0.8, "depth_error_m": 0.03}


def main(argv: Sequence[str] | None = None) -> int:
    return pages.main(pages.Study(HERE, run, collect, render, _arguments,
                                  description=__doc__.split("\n\n")[0]), argv)


def _arguments(run_parser: argparse.ArgumentParser,
               collect_parser: argparse.ArgumentParser) -> None:
    run_parser.add_argument("--captures", type=Path, default=CAPTURES,
                            help="folder of the Stanford .mat captures")
    run_parser.add_argument("--only", nargs="*", default=None, help="capture file stems to run")
    run_parser.add_argument("--dir", type=Path, default=None,
                            help="sweeps go to DIR/<stem> (default: multirun/imagers-<date>)")
    run_parser.add_argument("overrides", nargs="*", help="Hydra overrides for every sweep")
    collect_parser.add_argument("dirs", type=Path, nargs="+", help="one sweep per capture")
    for parser in (run_parser, collect_parser):
        parser.add_argument("--out", type=Path, default=None,
                            help="write the results here instead of results.json")


def sweep_command(sweep: Path, capture: Path, overrides: Sequence[str]) -> list[str]:
    """The sweep imaging ``capture`` with every imager."""
    return [sys.executable, "-m", "nlosfw", "-m",
            f"capture.path={override_value(str(capture.resolve()))}", "model=none",
            "output.keep=[reconstructions]", f"imager={','.join(IMAGERS)}",
            "reconstruction.histogram_reference=false",
            f"hydra.sweep.dir={override_value(str(sweep))}", *overrides]


def run(args: argparse.Namespace) -> None:
    """One sweep per capture (then ``collect`` reads them)."""
    from tests.image.lct_reference import AUTHORS_SCENES

    root = args.dir or ROOT / "multirun" / f"imagers-{time.strftime('%Y%m%d-%H%M%S')}"
    names = [n for n in AUTHORS_SCENES if not args.only or n in args.only]
    missing = [n for n in names if not (args.captures / f"{n}.mat").is_file()]
    if missing or not names:
        raise SystemExit(f"--captures: {args.captures} lacks {', '.join(missing) or 'captures'}")
    args.dirs = []
    for name in names:
        sweep = (root / name).resolve()
        command = sweep_command(sweep, args.captures / f"{name}.mat", args.overrides)
        print("$ " + shlex.join(command), flush=True)
        subprocess.run(command, check=True, cwd=ROOT)
        args.dirs.append(sweep)


def authors(capture: Path) -> tuple[np.ndarray, float, list[float]]:
    """The authors' LCT of ``capture``: (front view (Y, X), brightest depth, their window)."""
    import scipy.io

    from tests.image.lct_reference import AUTHORS_SCENES, authors_lct

    data = scipy.io.loadmat(capture)
    settings = dataclasses.replace(AUTHORS_SCENES[capture.stem], downsample=1)
    vol, z = authors_lct(data["rect_data"], float(np.squeeze(data["width"])), 4e-12, settings)
    brightest = float(z[np.unravel_index(int(np.argmax(vol)), vol.shape)[0]])
    return vol.max(axis=0), brightest, [float(z[0]), float(z[-1])]


def imaged(run_dir: Path) -> tuple[str, np.ndarray, float, dict[str, Any]]:
    """One run's imager, front view (Y, X; x and y ascending), brightest depth and facts."""
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    recon = read_reconstruction(run_dir / "reconstructions" / "true.hdf5")
    volume = amplitude(recon.intensity)                          # (Z, Y, X)
    depths = recon.voxels[:, 0, 0, 2]
    brightest = float(depths[np.unravel_index(int(np.argmax(volume)), volume.shape)[0]])
    band = recon.metadata.get("frequencies") or [0.0]
    facts = {"brightest_depth_m": brightest, "planes": int(depths.size),
             "seconds": metrics["timings"].get("reconstruct"),
             "falloff": recon.metadata.get("falloff"), "snr": recon.metadata.get("snr"),
             "band_per_m": [float(min(band)), float(max(band))]}
    return str(metrics["run"]["imager"]), volume.max(axis=0), brightest, facts


def _capture_of(run_dir: Path) -> Path | None:
    """The capture file a run imaged (its config's ``capture.path``)."""
    from nlosfw.report import read_run

    config = read_run(run_dir, run_dir.parent).config
    capture = config.get("capture") if isinstance(config, dict) else None
    path = capture.get("path") if isinstance(capture, dict) else None
    return Path(str(path)) if path else None


def collect(args: argparse.Namespace) -> dict[str, Any]:
    """Each capture's runs against the authors' LCT; prints the page's generated section."""
    captures: dict[str, Any] = {}
    for sweep in args.dirs:
        runs = sorted(p.parent for p in sweep.rglob("metrics.json"))
        path = _capture_of(runs[0]) if runs else None
        if path is None:
            raise SystemExit(f"{sweep}: no run of a capture file found")
        reference, their_depth, window = authors(path)
        entry: dict[str, Any] = {"authors": {"brightest_depth_m": their_depth,
                                             "depth_window_m": window}}
        for run_dir in runs:
            imager, front, brightest, facts = imaged(run_dir)
            facts["ncc"] = ncc(reference, front)
            facts["depth_error_m"] = brightest - their_depth
            entry[imager] = facts
        captures[path.stem] = entry
    results = {"question": QUESTION, "source": "the runs' volumes and metrics.json, read by "
               "`run.py collect`", "recorded": pages.recorded(), "captures": captures}
    print(results_markdown(results))
    return results


# ---------------------------------------------------------------------- the page
def results_markdown(results: dict[str, Any]) -> str:
    """The page's generated section, from the collected results."""
    captures = results["captures"]
    lines = ["| capture | authors' brightest depth (m) | "
             + " | ".join(IMAGERS) + " |", "|---|---|" + "---|" * len(IMAGERS)]
    met = True
    for name, entry in captures.items():
        cells = []
        for imager in IMAGERS:
            row = entry.get(imager)
            if row is None:
                cells.append("-")
                met = False
                continue
            met &= (row["ncc"] >= TARGETS["ncc"]
                    and abs(row["depth_error_m"]) <= TARGETS["depth_error_m"])
            cells.append(f"{row['ncc']:.2f} / {100 * row['depth_error_m']:.1f}")
        lines.append(f"| `{name}.mat` | {entry['authors']['brightest_depth_m']:.3f} | "
                     + " | ".join(cells) + " |")
    verdict = "All four meet" if met else "Not all of them meet"
    return "\n".join([
        "Generated by `python studies/classical_imagers_measured/run.py render` from "
        "`results.json`. " + pages.recorded_line(results),
        "",
        "Front-view normalised cross-correlation with the authors' LCT / brightest depth "
        "minus theirs (cm):",
        "",
        *lines,
        "",
        f"{verdict} NCC ≥ {TARGETS['ncc']:g} and {100 * TARGETS['depth_error_m']:g} cm on "
        f"all {len(captures)} captures.",
        "",
        f"![NCC and depth error of each imager per capture]({FIGURE})",
    ]) + "\n"


def render(results: dict[str, Any], folder: Path) -> None:
    """The page's generated section and ``figure.svg``, from ``results``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pages.replace_generated(folder / "README.md", results_markdown(results))
    captures = results["captures"]
    with matplotlib.rc_context(pages.plain_figure_settings()):
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
        width = 0.8 / len(IMAGERS)
        for k, imager in enumerate(IMAGERS):
            xs = [i + k * width for i in range(len(captures))]
            rows = [entry.get(imager) or {} for entry in captures.values()]
            axes[0].bar(xs, [r.get("ncc", np.nan) for r in rows], width, label=imager)
            axes[1].bar(xs, [100 * r.get("depth_error_m", np.nan) for r in rows], width,
                        label=imager)
        for ax, label, target in ((axes[0], "NCC with the authors' LCT", TARGETS["ncc"]),
                                  (axes[1], "brightest depth − authors' (cm)", None)):
            ax.set_xticks([i + 0.4 - width / 2 for i in range(len(captures))],
                          [n.removeprefix("data_") for n in captures], fontsize=8)
            ax.set_ylabel(label)
            if target is not None:
                ax.axhline(target, color="k", linewidth=0.5, linestyle="--")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        pages.save_figure(fig, folder / FIGURE)
        plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())

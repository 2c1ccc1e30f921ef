"""The classical and phasor-field imagers on the shared Stanford LCT captures (issue 21).

For each capture in ``../shared/data/real`` (or ``$NLOSFW_REAL_DATA``): the authors' LCT
(tests/lct_reference.py's ``authors_lct``: their MATLAB procedure, their per-scene falloff,
SNR and depth window; 8 ps bins, their ``K = 1``, to keep memory and time small), and
nlosfw's ``lct``, ``fk``, ``fbp`` and ``fft`` imagers with their defaults on the capture as
``nlosfw.load_capture`` reads it (the format's gate, the authors' settings as imaging hints),
at the automatic depths (``nlosfw.image.depths``): the transient imagers over the
measured-capture band (0.4-60 cycles/m, ``nlosfw.image.measured``), the phasor-field
``fft`` imager over the default transform's band (the wall's aliasing limit: it blurs the
charts below NCC 0.8 over the measured band, 0.77 and 0.62). Per imager:

* ``ncc``: normalised cross-correlation of the front view (the maximum over depth of the
  amplitude, sqrt of nlosfw's intensity) with the authors' front view (the maximum over
  their depth window of max(real, 0));
* ``depth_error_m``: the depth of the volume's brightest voxel minus the authors'.

Prints a table, writes ``benchmarks/results/real_imagers.json`` and, for the first capture,
``docs/images/real_imagers.png`` (the authors' LCT and the four side by side).

    nice python benchmarks/real_imagers.py [--captures data_diffuse_s ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.io

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from nlosfw import load_capture  # noqa: E402
from nlosfw.capture.hints import capture_hints  # noqa: E402
from nlosfw.image.depths import automatic_depths, depth_span  # noqa: E402
from nlosfw.image.measured import measured_field  # noqa: E402
from nlosfw.image.transient import canonical_wall  # noqa: E402
from nlosfw.plugins import load_plugins  # noqa: E402
from nlosfw.transform.fft import FFTTransform  # noqa: E402
from tests.lct_reference import AUTHORS_SCENES, authors_lct  # noqa: E402

REAL = Path(os.environ.get("NLOSFW_REAL_DATA") or ROOT.parent / "shared" / "data" / "real")
IMAGERS = ("lct", "fk", "fbp", "fft")
RESULTS = ROOT / "benchmarks" / "results" / "real_imagers.json"
FIGURE = ROOT / "docs" / "images" / "real_imagers.png"


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two images (Pearson's r of their pixels)."""
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def authors(name: str) -> tuple[np.ndarray, float, list[float]]:
    """(front view (Y, X) on the canonical grid, brightest depth, their window)."""
    data = scipy.io.loadmat(REAL / f"{name}.mat")
    settings = dataclasses.replace(AUTHORS_SCENES[name], downsample=1)
    vol, z = authors_lct(data["rect_data"], float(np.squeeze(data["width"])), 4e-12, settings)
    brightest = float(z[np.unravel_index(int(np.argmax(vol)), vol.shape)[0]])
    return vol.max(axis=0), brightest, [float(z[0]), float(z[-1])]


def nlosfw_images(name: str) -> tuple[dict[str, dict[str, object]], dict[str, np.ndarray]]:
    """Each imager's front view (canonical grid), brightest depth, seconds."""
    capture = load_capture(REAL / f"{name}.mat")
    fields = {"measured": measured_field(capture), "default": FFTTransform().transform(capture)}
    host = load_plugins()
    out: dict[str, dict[str, object]] = {}
    fronts: dict[str, np.ndarray] = {}
    for imager in IMAGERS:
        field = fields["default" if imager == "fft" else "measured"]
        depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                                  field.geometry.kind)
        grid = canonical_wall(field)
        voxels = np.repeat(field.wall_xyz[None], depths.size, axis=0)
        voxels[..., 2] = depths[:, None, None]
        rows = np.rint((field.wall_xyz[..., 1] - grid.origin[0]) / grid.spacing[0]).astype(int)
        cols = np.rint((field.wall_xyz[..., 0] - grid.origin[1]) / grid.spacing[1]).astype(int)
        start = time.perf_counter()
        recon = host.registry.create("imager", imager).reconstruct(field, voxels)
        seconds = time.perf_counter() - start
        amplitude = np.sqrt(recon.intensity)                      # (Z, Y, X) field order
        front = np.zeros(grid.shape)
        front[rows, cols] = amplitude.max(axis=0)
        fronts[imager] = front
        brightest = float(depths[np.unravel_index(int(np.argmax(amplitude)),
                                                  amplitude.shape)[0]])
        out[imager] = {"brightest_depth_m": brightest, "seconds": round(seconds, 2),
                       "falloff": recon.metadata.get("falloff"),
                       "snr": recon.metadata.get("snr"), "planes": int(depths.size),
                       "band_per_m": [float(field.frequencies.min()),
                                      float(field.frequencies.max())]}
    info = {"depth_range_m": list(depth_span(capture)),
            "hints": capture_hints(capture).to_dict()}
    out["_run"] = info
    return out, fronts


def figure(name: str, reference: np.ndarray, fronts: dict[str, np.ndarray],
           scores: dict[str, dict[str, object]]) -> None:
    """The authors' LCT and each imager's front view side by side (y up)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("authors' LCT (MATLAB procedure)", reference)] + [
        (f"nlosfw {k} · NCC {scores[k]['ncc']:.2f}", v) for k, v in fronts.items()]
    fig, axes = plt.subplots(1, len(panels), figsize=(3.0 * len(panels), 3.3))
    for ax, (title, image) in zip(axes, panels, strict=True):
        ax.imshow(image, origin="lower", cmap="gray")
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{name}.mat (O'Toole et al. 2018): front views", fontsize=10)
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE, dpi=100)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--captures", nargs="*", default=list(AUTHORS_SCENES))
    args = parser.parse_args()
    missing = [n for n in args.captures if not (REAL / f"{n}.mat").is_file()]
    if missing:
        print(f"shared captures absent in {REAL}: {', '.join(missing)}")
        return 2
    results: dict[str, object] = {}
    print(f"{'capture':28s} {'imager':6s} {'NCC':>6s} {'depth':>7s} {'authors':>7s} "
          f"{'error':>7s} {'s':>6s}")
    for index, name in enumerate(args.captures):
        reference, their_depth, window = authors(name)
        scores, fronts = nlosfw_images(name)
        for imager in IMAGERS:
            row = scores[imager]
            row["ncc"] = ncc(fronts[imager], reference)
            row["depth_error_m"] = float(row["brightest_depth_m"]) - their_depth  # type: ignore[arg-type]
            print(f"{name:28s} {imager:6s} {row['ncc']:6.3f} {row['brightest_depth_m']:7.3f} "
                  f"{their_depth:7.3f} {row['depth_error_m']:+7.3f} {row['seconds']:6.1f}")
        scores["authors"] = {"brightest_depth_m": their_depth, "depth_window_m": window}
        results[name] = scores
        if index == 0:
            figure(name, reference, fronts, scores)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {RESULTS.relative_to(ROOT)} and {FIGURE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

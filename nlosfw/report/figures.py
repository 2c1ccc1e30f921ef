"""Figures of a run (PNG): phasor fields, reconstructions, loss curves.

``fields_f<k>.png``  amplitude, phase and amplitude error of each field at one
                     training and one held-out frequency (as in thesis figs. 4.2-5.5)
``reconstructions.png``  front views (amplitude, the maximum over depth: what the scores
                     compare) of every source, their depth maps and their error
                     against the reconstruction of the true field
``reconstructions_f<k>.png``  the same from frequency k alone (thesis figs. 5.1-5.5)
``loss.png``         training (and validation) loss of each field model

and the views of every source and the capture's time profile (:mod:`nlosfw.report.views`),
with the front view and depth map of the reference picture (``front_native-bins.png``,
``depth_native-bins.png``: the measured histograms at their native bin width, not scored)
when the run made one; a ``model=none``
run (the capture imaged alone) has only those.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np
from matplotlib.figure import Figure

from nlosfw.evaluation.image_scores import amplitude, normalise
from nlosfw.evaluation.reference import REFERENCE, REFERENCE_TITLE
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.pipeline.files import RunFiles
from nlosfw.pipeline.metrics import ImageScores, ReconstructionMetrics, RunInfo
from nlosfw.pipeline.results import RunResults
from nlosfw.report.plain_text import save_literal
from nlosfw.report.titles import run_title
from nlosfw.report.views import write_source_views, write_views
from nlosfw.transform.field import PhasorField

if TYPE_CHECKING:
    from matplotlib.axes import Axes

_SOURCE_TITLES = {"true": "true field", "raw": "raw (training samples)",
                  "interp": "interp baseline", "ceiling": "ceiling (half A's full scan)"}


#: The viewpoint of every reconstruction image, stated on the figures.
VIEWPOINT = ("view along depth z from the relay wall into the hidden scene; "
             "x, y in the wall's coordinates (m)")


class DepthScale(TypedDict):
    """The colour scale of the depth row (``imshow`` keywords)."""

    cmap: str
    vmin: float
    vmax: float


def write_figures(files: RunFiles, results: RunResults, info: RunInfo,
                  scores: ReconstructionMetrics, dpi: int) -> None:
    """Write every figure of a run into ``figures/``.

    The fields at each single frequency the reconstructions show, the
    reconstructions (whole band and single frequencies, labelled with their
    ``scores``, beside the scene's ground-truth depth when the capture has one)
    and the loss curves; each titled with the run (:func:`run_title`).
    """
    title = run_title(info, results.capture)
    labels = source_labels(results)
    recons = results.reconstructions
    write_views(files, recons.by_source, labels, results.capture.capture, title, dpi)
    if recons.reference is not None:
        write_source_views(files, {REFERENCE: recons.reference},
                           {REFERENCE: "reference (native bins)"},
                           f"{title}\n{reference_caption(recons.reference)}", dpi,
                           views=("front", "depth"))
    if results.fields is None or results.fit is None:
        return  # model=none: the capture imaged alone, nothing to compare
    fields = results.fields.by_source()
    truth_depth = results.capture.truth_depth
    for single in recons.single_frequency:
        files.write(f"figures/fields_f{single.index}.png",
                  _saver(partial(field_figure, fields, single.index,
                                 f"a {single.split} frequency\n{title}", labels), dpi),
                  kind="figure")
    band = results.fields.true.frequencies
    whole = (f"{title}\nall {band.size} frequencies "
             f"({band.min():.2f}-{band.max():.2f} cycles/m)")
    files.write("figures/reconstructions.png",
              _saver(lambda: reconstruction_figure(recons.by_source, scores.sources,
                                                   truth_depth, whole, labels), dpi),
              kind="figure")
    for single in recons.single_frequency:
        entry = scores.single_frequency[str(single.index)]
        label = (f"{title}\nthe single {entry.split} frequency f = {entry.frequency:.3f} "
                 f"cycles/m (λ = {100 / entry.frequency:.1f} cm)")
        files.write(f"figures/reconstructions_f{single.index}.png",
                  _saver(partial(reconstruction_figure, single.by_source, entry.sources,
                                 truth_depth, label, labels), dpi), kind="figure")
    histories = {m.source: m.report.history for m in results.fit.models if m.report.history}
    if histories:
        files.write("figures/loss.png", _saver(lambda: loss_figure(histories, title), dpi),
                  kind="figure")


def _saver(make: Callable[[], Figure], dpi: int) -> Callable[[Path], None]:
    def save(path: Path) -> None:
        save_literal(make, path, dpi)

    return save


def _extent(field: PhasorField) -> list[float]:
    w = field.wall_xyz
    sp = field.grid_spacing() or (0.0, 0.0)
    return [w[0, 0, 0] - sp[1] / 2, w[0, -1, 0] + sp[1] / 2,
            w[0, 0, 1] - sp[0] / 2, w[-1, 0, 1] + sp[0] / 2]


def source_labels(results: RunResults) -> dict[str, str]:
    """How the figures name each source: the model by its plugin, a ``compare`` label with
    its plugin (``pe (pe_torch)``), the others by their role."""
    if results.fit is None:  # model=none
        return {"true": "the capture (every sample)"}
    labels = {m.source: (m.plugin if m.source == "model" else
                         _SOURCE_TITLES.get(m.source, f"{m.source} ({m.plugin})"))
              for m in results.fit.models}
    return {"true": _SOURCE_TITLES["true"], "raw": _SOURCE_TITLES["raw"], **labels}


def reference_caption(recon: Reconstruction) -> str:
    """What the reference picture's views show (under the run's title): what it is, its
    band, not scored."""
    freqs = np.asarray(recon.metadata.get("frequencies") or [], dtype=float)
    band = f"\n({freqs.size} DFT bins to {freqs.max():.4g} cycles/m)" if freqs.size else ""
    return f"{REFERENCE_TITLE}, not scored{band}"


def field_figure(fields: Mapping[str, PhasorField], index: int, title: str,
                 labels: Mapping[str, str] | None = None) -> Figure:
    """Amplitude, phase and amplitude error of every field at frequency ``index``.

    One row per field (``true`` first), one column per quantity; the panels of a column
    share one colour scale and its colorbar. Axes are the relay wall's x, y (m).
    """
    true = fields["true"]
    sources = list(fields)
    names = {s: (labels or {}).get(s, _SOURCE_TITLES.get(s, s)) for s in sources}
    amp_max = float(np.abs(true.values[index]).max()) or 1.0
    errors = {s: np.abs(fields[s].values[index] - true.values[index]) / amp_max
              for s in sources if s not in ("true", "raw")}
    err_max = _shared_scale(errors.values())
    fig = Figure(figsize=(10.5, 2.9 * len(sources) + 0.9), layout="constrained")
    axes = fig.subplots(len(sources), 3, squeeze=False)
    freq = true.frequencies[index]
    fig.suptitle(f"phasor fields on the relay wall at f = {freq:.3f} cycles/m "
                 f"(λ = {100 / freq:.1f} cm), {title}")
    images = {}
    for row, source in enumerate(sources):
        values = fields[source].values[index]
        ext = _extent(fields[source])
        ax = axes[row]
        images["amp"] = ax[0].imshow(np.abs(values) / amp_max, origin="lower", extent=ext,
                                     vmin=0, vmax=1, cmap="magma")
        ax[0].set_title(f"{names[source]}: amplitude")
        images["phase"] = ax[1].imshow(np.angle(values), origin="lower", extent=ext,
                                       vmin=-np.pi, vmax=np.pi, cmap="twilight")
        ax[1].set_title(f"{names[source]}: phase")
        if source in ("true", "raw"):
            ax[2].axis("off")
            ax[2].text(0.5, 0.5, "(the reference)" if source == "true" else
                       "(the training samples:\nno error to show)", ha="center", va="center",
                       transform=ax[2].transAxes, color="0.4")
            continue
        images["err"] = ax[2].imshow(errors[source], origin="lower", extent=ext, vmin=0,
                                     vmax=err_max, cmap="viridis")
        ax[2].set_title(f"{names[source]}: amplitude error")
    for ax in axes.ravel():
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.colorbar(images["amp"], ax=axes[:, 0], shrink=0.6, location="bottom",
                 label="|P| / max |P of the true field|")
    fig.colorbar(images["phase"], ax=axes[:, 1], shrink=0.6, location="bottom",
                 label="arg P (rad)")
    if "err" in images:
        fig.colorbar(images["err"], ax=axes[:, 2], shrink=0.6, location="bottom",
                     label="|P - P of the true field| / max |P of the true field|\n"
                           "(99th percentile = top)")
    return fig


def reconstruction_figure(recons: Mapping[str, Reconstruction],
                          scores: Mapping[str, ImageScores], truth_depth: np.ndarray | None,
                          title: str, labels: Mapping[str, str] | None = None) -> Figure:
    """Every source's reconstruction side by side, one column each (``true`` first).

    Rows: the brightest voxel over depth (each image normalised to its maximum), the
    depth of that voxel, and the difference from the true field's image (under ``true``:
    the scene's ground-truth depth when known). Each row shares one colour scale and one
    colorbar; the viewpoint (:data:`VIEWPOINT`) is stated under the title.
    """
    sources = list(recons)
    names = {s: (labels or {}).get(s, _SOURCE_TITLES.get(s, s)) for s in sources}
    images = {s: normalise(amplitude(recons[s].max_intensity_image())) for s in sources}
    reference = images["true"]
    errors = {s: np.abs(images[s] - reference) for s in sources if s != "true"}
    err_max = _shared_scale(errors.values())
    fig = Figure(figsize=(3.1 * len(sources) + 1.2, 9.6), layout="constrained")
    axes = fig.subplots(3, len(sources), squeeze=False)
    vox = recons["true"].voxels
    ext = [vox[0, 0, 0, 0], vox[0, 0, -1, 0], vox[0, 0, 0, 1], vox[0, -1, 0, 1]]
    depths = recons["true"].depths
    depth_scale = DepthScale(cmap="viridis", vmin=float(depths.min()), vmax=float(depths.max()))
    mappable = {}
    for col, source in enumerate(sources):
        mappable["intensity"] = axes[0, col].imshow(images[source], origin="lower", extent=ext,
                                                    cmap="hot", vmin=0, vmax=1)
        score = _score_label(scores.get(source), source)
        axes[0, col].set_title(names[source] + (f"\n{score}" if score else ""), fontsize=10)
        depth = recons[source].depth_map(threshold=0.1)
        mappable["depth"] = axes[1, col].imshow(depth, origin="lower", extent=ext,
                                                **depth_scale)
        axes[1, col].set_title(f"{names[source]}: depth")
        if source == "true":
            _truth_panel(axes[2, col], truth_depth, depth_scale, ext)
            continue
        mappable["error"] = axes[2, col].imshow(errors[source], origin="lower", extent=ext,
                                                cmap="viridis", vmin=0, vmax=err_max)
        axes[2, col].set_title(f"{names[source]}: |image - true's|")
    for ax in axes.ravel():
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.colorbar(mappable["intensity"], ax=axes[0, :], shrink=0.9,
                 label="amplitude (√intensity), max over depth\n(each image / its maximum)")
    fig.colorbar(mappable["depth"], ax=axes[1, :], shrink=0.9,
                 label="depth of the brightest voxel (m)\n(blank: below 10 % of the maximum)")
    if "error" in mappable:
        fig.colorbar(mappable["error"], ax=axes[2, :], shrink=0.9,
                     label="|image - true field's image|\n(99th percentile = top)")
    fig.suptitle(f"reconstructions from {title}\n{VIEWPOINT}")
    return fig


def _score_label(scores: ImageScores | None, source: str) -> str:
    """'PSNR 31.2 dB, SSIM 0.812 vs true' for a scored source other than the reference
    (nothing otherwise)."""
    if scores is None or source == "true":
        return ""
    parts = [f"PSNR {scores.psnr:.1f} dB" if scores.psnr is not None else "",
             f"SSIM {scores.ssim:.3f}" if scores.ssim is not None else ""]
    shown = ", ".join(p for p in parts if p)
    return f"{shown} vs true" if shown else ""


def _truth_panel(ax: Axes, truth_depth: np.ndarray | None, depth_scale: DepthScale,
                 extent: list[float]) -> None:
    """The scene's ground-truth depth as seen from the wall (when the capture carries one),
    on the depth row's colour scale.

    The maps cover the wall, which is also the extent of the voxel planes.
    """
    if truth_depth is None:
        ax.axis("off")
        ax.text(0.5, 0.5, "(no ground truth:\na captured scene)", ha="center", va="center",
                transform=ax.transAxes, color="0.4")
        return
    depth = np.asarray(truth_depth, dtype=float).T          # (X, Y) -> (Y, X) image
    depth = np.where(depth > 0, depth, np.nan)
    ax.imshow(depth, origin="lower", extent=(extent[0], extent[1], extent[2], extent[3]),
              **depth_scale)
    ax.set_title("ground truth: depth\n(depth row's colour scale)")


def _shared_scale(maps: Iterable[np.ndarray]) -> float:
    """One colour scale for several error maps: the largest 99th percentile (outliers clip)."""
    values = [float(np.percentile(m, 99)) for m in maps if np.size(m)]
    return max(values + [1e-12])


def loss_figure(histories: Mapping[str, list[dict[str, float]]], title: str) -> Figure:
    """Training (and validation) loss of each field model against the step."""
    fig = Figure(figsize=(6.5, 4.3), layout="constrained")
    ax = fig.subplots()
    ax.set_title(f"training loss\n{title}", fontsize=10)
    for source, history in histories.items():
        steps = [h.get("step", i) for i, h in enumerate(history)]
        ax.plot(steps, [h.get("loss", np.nan) for h in history], label=f"{source} train")
        if any(h.get("val_loss") is not None for h in history):
            val = [np.nan if (v := h.get("val_loss")) is None else v for h in history]
            ax.plot(steps, val, "--", label=f"{source} validation")
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss (normalised MSE)")
    ax.legend()
    ax.grid(alpha=0.3)
    return fig

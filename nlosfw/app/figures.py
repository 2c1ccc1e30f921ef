"""Figures of a run (PNG): phasor fields, reconstructions, loss curves.

``fields_f<k>.png``  amplitude, phase and amplitude error of each field at one
                     training and one held-out frequency (as in thesis figs. 4.2-5.5)
``reconstructions.png``  max-intensity images of every source, their depth maps
                     and their error against the reconstruction of the true field
``reconstructions_f<k>.png``  the same from frequency k alone (thesis figs. 5.1-5.5)
``loss.png``         training (and validation) loss of each field model
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from nlosfw.app.metrics import ImageScores, ReconstructionMetrics
from nlosfw.app.results import RunResults
from nlosfw.app.run_dir import RunContext
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.scores import normalise
from nlosfw.transform.field import PhasorField

_SOURCE_TITLES = {"true": "true field", "raw": "raw (training grid)", "model": "model",
                  "interp": "interp baseline"}


def write_figures(ctx: RunContext, results: RunResults, scores: ReconstructionMetrics,
                  dpi: int) -> None:
    """Write every figure of a run into ``figures/``.

    The fields at each single frequency the reconstructions show, the
    reconstructions (whole band and single frequencies, labelled with their
    ``scores``, beside the scene's ground-truth depth when the capture has one)
    and the loss curves.
    """
    fields = results.fields.by_source()
    recons = results.reconstructions
    truth_depth = results.capture.truth_depth
    run = results.capture.label
    for single in recons.single_frequency:
        ctx.write(f"figures/fields_f{single.index}.png",
                  _saver(partial(_field_figure, fields, single.index, single.split, run), dpi),
                  kind="figure")
    ctx.write("figures/reconstructions.png",
              _saver(lambda: _recon_figure(recons.by_source, scores.sources, truth_depth,
                                           f"{run} from all frequencies"), dpi), kind="figure")
    for single in recons.single_frequency:
        entry = scores.single_frequency[str(single.index)]
        title = (f"{run} from f = {entry.frequency:.3f} cycles/m only ({entry.split} "
                 "frequency)")
        ctx.write(f"figures/reconstructions_f{single.index}.png",
                  _saver(partial(_recon_figure, single.by_source, entry.sources, truth_depth,
                                 title), dpi), kind="figure")
    histories = {m.source: m.report.history for m in results.fit.models if m.report.history}
    if histories:
        ctx.write("figures/loss.png", _saver(lambda: _loss_figure(histories), dpi), kind="figure")


def _saver(make: Callable[[], Any], dpi: int) -> Callable[[Path], None]:
    def save(path: Path) -> None:
        make().savefig(path, dpi=dpi, format="png", bbox_inches="tight")

    return save


def _extent(field: PhasorField) -> list[float]:
    w = field.wall_xyz
    sp = field.grid_spacing() or (0.0, 0.0)
    return [w[0, 0, 0] - sp[1] / 2, w[0, -1, 0] + sp[1] / 2,
            w[0, 0, 1] - sp[0] / 2, w[-1, 0, 1] + sp[0] / 2]


def _field_figure(fields: Mapping[str, PhasorField], index: int, label: str, run: str) -> Any:
    true = fields["true"]
    sources = list(fields)
    amp_max = float(np.abs(true.values[index]).max()) or 1.0
    errors = {s: np.abs(fields[s].values[index] - true.values[index]) / amp_max
              for s in sources if s not in ("true", "raw")}
    err_max = _shared_scale(errors.values())
    fig = Figure(figsize=(9.5, 3.0 * len(sources)))
    axes = fig.subplots(len(sources), 3, squeeze=False)
    freq = true.frequencies[index]
    fig.suptitle(f"{run}: phasor field at f = {freq:.3f} cycles/m (λ = {100 / freq:.1f} cm), "
                 f"{label} frequency")
    for row, source in enumerate(sources):
        values = fields[source].values[index]
        ext = _extent(fields[source])
        ax = axes[row]
        im = ax[0].imshow(np.abs(values) / amp_max, origin="lower", extent=ext, vmin=0,
                          vmax=1, cmap="magma")
        ax[0].set_title(f"{_SOURCE_TITLES.get(source, source)}: |P| / max |P_true|")
        fig.colorbar(im, ax=ax[0], fraction=0.046)
        im = ax[1].imshow(np.angle(values), origin="lower", extent=ext, vmin=-np.pi,
                          vmax=np.pi, cmap="twilight")
        ax[1].set_title("phase (rad)")
        fig.colorbar(im, ax=ax[1], fraction=0.046)
        if source in ("true", "raw"):
            ax[2].axis("off")
            continue
        im = ax[2].imshow(errors[source], origin="lower", extent=ext, vmin=0, vmax=err_max,
                          cmap="viridis")
        ax[2].set_title("|P - P_true| / max |P_true|")
        fig.colorbar(im, ax=ax[2], fraction=0.046)
    for ax in axes.ravel():
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.tight_layout()
    return fig


def _recon_figure(recons: Mapping[str, Reconstruction], scores: Mapping[str, ImageScores],
                  truth_depth: np.ndarray | None, title: str) -> Any:
    sources = list(recons)
    reference = normalise(recons["true"].max_intensity_image())
    images = {s: normalise(recons[s].max_intensity_image()) for s in sources}
    errors = {s: np.abs(images[s] - reference) for s in sources if s != "true"}
    err_max = _shared_scale(errors.values())
    fig = Figure(figsize=(3.3 * len(sources), 9.5))
    axes = fig.subplots(3, len(sources), squeeze=False)
    vox = recons["true"].voxels
    ext = [vox[0, 0, 0, 0], vox[0, 0, -1, 0], vox[0, 0, 0, 1], vox[0, -1, 0, 1]]
    depths = recons["true"].depths
    for col, source in enumerate(sources):
        ssim = None if source not in scores else scores[source].ssim
        label = "" if ssim is None or source == "true" else f"  (SSIM {ssim:.3f})"
        axes[0, col].imshow(images[source], origin="lower", extent=ext, cmap="hot", vmin=0,
                            vmax=1)
        axes[0, col].set_title(f"{_SOURCE_TITLES.get(source, source)}{label}\n"
                               "max intensity over depth")
        depth = recons[source].depth_map(threshold=0.1)
        im = axes[1, col].imshow(depth, origin="lower", extent=ext, cmap="viridis",
                                 vmin=depths.min(), vmax=depths.max())
        axes[1, col].set_title("depth of the maximum (m)")
        fig.colorbar(im, ax=axes[1, col], fraction=0.046)
        if source == "true":
            _truth_panel(fig, axes[2, col], truth_depth, depths, ext)
            continue
        im = axes[2, col].imshow(errors[source], origin="lower", extent=ext, cmap="viridis",
                                 vmin=0, vmax=err_max)
        axes[2, col].set_title("|image - true field's image|")
        fig.colorbar(im, ax=axes[2, col], fraction=0.046)
    for ax in axes.ravel():
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    fig.suptitle(f"reconstructions of {title}")
    fig.tight_layout()
    return fig


def _truth_panel(fig: Any, ax: Any, truth_depth: np.ndarray | None, depths: np.ndarray,
                 extent: list[float]) -> None:
    """The scene's ground-truth depth as seen from the wall (when the capture carries one).

    The maps cover the wall, which is also the extent of the voxel planes.
    """
    if truth_depth is None:
        ax.axis("off")
        return
    depth = np.asarray(truth_depth, dtype=float).T          # (X, Y) -> (Y, X) image
    depth = np.where(depth > 0, depth, np.nan)
    im = ax.imshow(depth, origin="lower", extent=extent, cmap="viridis",
                   vmin=depths.min(), vmax=depths.max())
    ax.set_title("ground truth: depth seen\nfrom the wall (m)")
    fig.colorbar(im, ax=ax, fraction=0.046)


def _shared_scale(maps: Any) -> float:
    """One colour scale for several error maps: the largest 99th percentile (outliers clip)."""
    values = [float(np.percentile(m, 99)) for m in maps if np.size(m)]
    return max(values + [1e-12])


def _loss_figure(histories: dict[str, list[dict[str, float]]]) -> Any:
    fig = Figure(figsize=(6.5, 4))
    ax = fig.subplots()
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
    fig.tight_layout()
    return fig

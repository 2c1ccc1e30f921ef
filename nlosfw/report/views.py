"""The views a researcher looks at (PNG), per imaged source, and the capture's time profile.

``front_<source>.png``   the front view: the brightest voxel of each (y, x) column over
                         the reconstruction's depth planes (the signal's depth range)
``depth_<source>.png``   the depth of that voxel, blank where the column holds no signal
                         (its brightest voxel below :data:`SIGNAL_FRACTION` of the volume's)
``slices_<source>.png``  a strip of depth slices through the volume, one colour scale
``time_profile.png``     the capture's histograms summed over the wall against the optical
                         path (and time), with the depth range the planes span marked

The numbers behind them (:func:`front_view`, :func:`masked_depth_map`,
:func:`time_profile`, :func:`round_trip_path`) are plain functions, drawn by the figure
functions; titles come from the caller (:func:`nlosfw.report.titles.run_title`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path

import numpy as np
from matplotlib.colors import Colormap
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from nlosfw.capture.data import Capture
from nlosfw.common.text import plain_title
from nlosfw.evaluation.image_scores import amplitude, normalise
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.pipeline.files import RunFiles

#: The depth map is blank where a column's brightest voxel is below this fraction of the
#: volume's brightest (intensity; 0.1 is about a third of the amplitude).
SIGNAL_FRACTION = 0.1

#: At most this many depth slices in a strip (evenly spaced over the planes).
MAX_SLICES = 12

#: Slices per row of the strip.
SLICES_PER_ROW = 6

#: Speed of light (m per ns): the time axis of the time profile.
_C_M_PER_NS = 0.299792458

#: The viewpoint of every image, stated on the figures.
_VIEW = "seen from the relay wall along depth z; x, y in the wall's coordinates (m)"


def front_view(recon: Reconstruction) -> np.ndarray:
    """Amplitude of each (y, x) column's brightest voxel over all planes, over its maximum."""
    return normalise(amplitude(recon.max_intensity_image()))


def masked_depth_map(recon: Reconstruction, fraction: float = SIGNAL_FRACTION) -> np.ndarray:
    """Depth (m) of each column's brightest voxel, (Y, X); NaN where that voxel is at most
    ``fraction`` of the volume's brightest intensity (no signal)."""
    return recon.depth_map(threshold=fraction)


def time_profile(capture: Capture) -> tuple[np.ndarray, np.ndarray]:
    """(optical path of each bin's centre (m), the histograms summed over the wall): where
    in time the capture holds light. A capture stored in frequency has none (empty arrays)."""
    if not capture.is_time_domain:
        return np.zeros(0), np.zeros(0)
    counts = np.abs(np.asarray(capture.H)).reshape(capture.n_bins, -1).sum(axis=1,
                                                                        dtype=np.float64)
    return np.asarray(capture.bin_centers, dtype=np.float64), counts


def round_trip_path(capture: Capture, depths: np.ndarray) -> np.ndarray:
    """The optical path (m) of light from a point straight ahead at each depth: 2 z (wall
    to the point and back) plus the mean device legs when the time axis includes them."""
    legs = float(np.mean(capture.geometry.device_path(capture.sensor_points)))
    return 2.0 * np.asarray(depths, dtype=np.float64) + legs


def depth_scale(depth: np.ndarray, planes: np.ndarray,
                least: float = 0.05) -> tuple[float, float]:
    """The colour scale of a depth map: the 1st to 99th percentile of the depths that hold
    signal (so a surface's relief shows), at least ``least`` metres wide, within the planes;
    all the planes when nothing holds signal."""
    lo_plane, hi_plane = float(np.min(planes)), float(np.max(planes))
    shown = depth[np.isfinite(depth)]
    if shown.size == 0:
        return lo_plane, hi_plane
    lo, hi = (float(v) for v in np.percentile(shown, [1, 99]))
    pad = max(0.0, least - (hi - lo)) / 2
    return max(lo_plane, lo - pad), min(hi_plane, hi + pad)


def slice_indices(n_planes: int, count: int = MAX_SLICES) -> np.ndarray:
    """Up to ``count`` plane indices evenly spread from the first plane to the last."""
    if n_planes <= count:
        return np.arange(n_planes)
    return np.unique(np.round(np.linspace(0, n_planes - 1, count)).astype(int))


def write_views(files: RunFiles, recons: Mapping[str, Reconstruction],
                labels: Mapping[str, str], capture: Capture, title: str, dpi: int) -> None:
    """Every view of every source (:func:`write_source_views`) and the capture's
    ``time_profile.png`` (:func:`write_time_profile`) into ``figures/``."""
    write_source_views(files, recons, labels, title, dpi)
    first = next(iter(recons.values()), None)
    if first is not None:
        write_time_profile(files, capture, (float(first.depths.min()),
                                            float(first.depths.max())), title, dpi)


def write_source_views(files: RunFiles, recons: Mapping[str, Reconstruction],
                       labels: Mapping[str, str], title: str, dpi: int,
                       views: tuple[str, ...] = ("front", "depth", "slices")) -> None:
    """``<view>_<source>.png`` of every source into ``figures/`` for each of ``views``
    (``front``, ``depth``, ``slices``), each named by its label (else the source's name)."""
    draws = {"front": front_figure, "depth": depth_figure, "slices": slices_figure}
    for source, recon in recons.items():
        name = labels.get(source, source)
        for view in views:
            files.write(f"figures/{view}_{source}.png",
                        _saver(partial(draws[view], recon, name, title), dpi), kind="figure")


def write_time_profile(files: RunFiles, capture: Capture, depth_range: tuple[float, float],
                       title: str, dpi: int) -> None:
    """``figures/time_profile.png`` with ``depth_range`` (m) shaded; nothing for a capture
    stored in frequency (it has no time profile)."""
    path, _ = time_profile(capture)
    if path.size:
        files.write("figures/time_profile.png",
                    _saver(partial(time_profile_figure, capture, depth_range, title), dpi),
                    kind="figure")


def _saver(make: Callable[[], Figure], dpi: int) -> Callable[[Path], None]:
    def save(path: Path) -> None:
        make().savefig(path, dpi=dpi, format="png")

    return save


def _extent(recon: Reconstruction) -> tuple[float, float, float, float]:
    """The lateral extent of the planes, from cell edge to cell edge when evenly spaced."""
    _, voxels = recon.as_volume()
    xs, ys = voxels[0, 0, :, 0], voxels[0, :, 0, 1]
    dx = float(xs[1] - xs[0]) / 2 if xs.size > 1 else 0.0
    dy = float(ys[1] - ys[0]) / 2 if ys.size > 1 else 0.0
    return (float(xs[0]) - dx, float(xs[-1]) + dx, float(ys[0]) - dy, float(ys[-1]) + dy)


def _range_text(recon: Reconstruction) -> str:
    depths = recon.depths
    return (f"{depths.size} planes, z = {depths.min():.3f}-{depths.max():.3f} m"
            if depths.size > 1 else f"the plane z = {depths[0]:.3f} m")


def front_figure(recon: Reconstruction, name: str, title: str) -> Figure:
    """The front view (:func:`front_view`) of one source."""
    return _map_figure(recon, front_view(recon), plain_title(title),
                       f"{plain_title(name)}: front view, max over {_range_text(recon)}",
                       "amplitude (√intensity) / its maximum", ("hot", 0.0, 1.0))


def depth_figure(recon: Reconstruction, name: str, title: str,
                 fraction: float = SIGNAL_FRACTION) -> Figure:
    """The depth map (:func:`masked_depth_map`) of one source; no signal is grey."""
    from matplotlib import colormaps

    depth = masked_depth_map(recon, fraction)
    low, high = depth_scale(depth, recon.depths)
    return _map_figure(recon, depth, plain_title(title),
                       f"{plain_title(name)}: depth of the brightest voxel\n(grey: below "
                       f"{fraction:.0%} of the brightest intensity, no signal)",
                       "depth z (m), scaled to the depths with signal",
                       (colormaps["viridis"].with_extremes(bad="0.85"), low, high))


def _map_figure(recon: Reconstruction, values: np.ndarray, title: str, map_title: str,
                colour_label: str, scale: tuple[str | Colormap, float, float]) -> Figure:
    """One (y, x) map over the wall's extent, with its colour bar and the run's title;
    ``scale``: the colour map and the values at its ends; the texts escaped already."""
    cmap, vmin, vmax = scale
    fig = Figure(figsize=(5.4, 5.0), layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(values, origin="lower", extent=_extent(recon), cmap=cmap, vmin=vmin,
                      vmax=vmax)
    ax.set_title(map_title, fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.colorbar(image, ax=ax, shrink=0.85, label=colour_label)
    fig.suptitle(f"{title}\n{_VIEW}", fontsize=8)
    return fig


def slices_figure(recon: Reconstruction, name: str, title: str,
                  count: int = MAX_SLICES) -> Figure:
    """A strip of up to ``count`` depth slices, each the amplitude over the volume's maximum
    (one colour scale: a faint slice looks faint)."""
    volume, _ = recon.as_volume()
    amp = amplitude(volume)
    peak = float(amp.max()) or 1.0
    chosen = slice_indices(amp.shape[0], count)
    cols = min(SLICES_PER_ROW, chosen.size)
    rows = math.ceil(chosen.size / cols)
    fig = Figure(figsize=(2.3 * cols + 0.9, 2.35 * rows + 0.9), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    extent = _extent(recon)
    depths = recon.depths
    image = None
    for ax, index in zip(axes.ravel(), chosen, strict=False):
        image = ax.imshow(amp[index] / peak, origin="lower", extent=extent, cmap="hot",
                          vmin=0, vmax=1)
        ax.set_title(f"z = {depths[index]:.3f} m", fontsize=8)
        ax.tick_params(labelsize=6)
    for ax in axes.ravel()[chosen.size:]:
        ax.axis("off")
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.8, label="amplitude / the volume's maximum")
    fig.suptitle(f"{plain_title(name)}: {chosen.size} depth slices of {depths.size} "
                 f"({_range_text(recon)})\n{plain_title(title)}", fontsize=8)
    return fig


def time_profile_figure(capture: Capture, depth_range: tuple[float, float],
                        title: str) -> Figure:
    """The capture's time profile (:func:`time_profile`), with the optical paths of the
    depth range the planes span (:func:`round_trip_path`) shaded."""
    path, counts = time_profile(capture)
    near, far = round_trip_path(capture, np.asarray(depth_range))
    fig = Figure(figsize=(8.0, 3.8), layout="constrained")
    ax = fig.subplots()
    ax.plot(path, counts, lw=0.9, color="C0")
    ax.axvspan(float(near), float(far), color="C1", alpha=0.2,
               label=f"the planes' depths {depth_range[0]:.3f}-{depth_range[1]:.3f} m "
                     "(round trip)")
    ax.set_yscale("symlog", linthresh=max(float(np.max(counts)) * 1e-4, 1e-12))
    ax.set_xlabel("optical path (m)")
    ax.set_ylabel("sum over the wall")
    top = ax.secondary_xaxis("top", functions=(_path_to_ns, _ns_to_path))
    top.set_xlabel("time (ns)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title("time profile of the capture (histograms summed over the wall)\n"
                 + plain_title(title), fontsize=9)
    return fig


def _path_to_ns(path: ArrayLike) -> np.ndarray:
    return np.asarray(path, dtype=np.float64) / _C_M_PER_NS


def _ns_to_path(ns: ArrayLike) -> np.ndarray:
    return np.asarray(ns, dtype=np.float64) * _C_M_PER_NS

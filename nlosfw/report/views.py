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
    h = np.abs(np.asarray(capture.H))
    counts = h.sum(axis=tuple(range(1, h.ndim)), dtype=np.float64)    # no reshaped copy
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
    width, height = 5.4, 5.0
    fig = Figure(figsize=(width, height))
    suptitle = f"{title}\n{_VIEW}"
    top = 1 - (_text_inches(suptitle, 8) + _text_inches(map_title, 9) + 0.2) / height
    extent = _extent(recon)
    aspect = abs(extent[3] - extent[2]) / max(abs(extent[1] - extent[0]), 1e-12)
    room = (top * height - 0.6, 3.2)                        # the map's (height, width), in
    box_w = min(room[1], room[0] / aspect)
    box_h = box_w * aspect
    left, bottom = 0.8 + (room[1] - box_w) / 2, 0.6 + (room[0] - box_h) / 2
    ax = fig.add_axes((left / width, bottom / height, box_w / width, box_h / height))
    image = ax.imshow(values, origin="lower", extent=extent, cmap=cmap, vmin=vmin, vmax=vmax)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    cax = fig.add_axes(((left + box_w + 0.2) / width, (bottom + 0.075 * box_h) / height,
                        0.14 / width, 0.85 * box_h / height))
    fig.colorbar(image, cax=cax, label=colour_label)
    fig.suptitle(suptitle, fontsize=8, y=1 - 0.05 / height, va="top")
    fig.text(0.5, (bottom + box_h + 0.1) / height, map_title, fontsize=9, ha="center",
             va="bottom")
    return fig


def _text_inches(text: str, fontsize: float) -> float:
    """The height (inches) of ``text``'s lines at ``fontsize`` points, line spacing 1.2."""
    return (text.count("\n") + 1) * fontsize * 1.2 / 72


def slices_figure(recon: Reconstruction, name: str, title: str,
                  count: int = MAX_SLICES) -> Figure:
    """A strip of up to ``count`` depth slices, each the amplitude over the volume's maximum
    (one colour scale: a faint slice looks faint), tiled into one image (each tile as the
    front view: x to the right, y up)."""
    volume, _ = recon.as_volume()
    amp = amplitude(volume)
    peak = float(amp.max()) or 1.0
    chosen = slice_indices(amp.shape[0], count)
    cols = min(SLICES_PER_ROW, chosen.size)
    rows = math.ceil(chosen.size / cols)
    ny, nx = amp.shape[1:]
    gap = max(1, round(0.06 * max(ny, nx)))
    label = max(2, round(0.22 * ny))                      # room above each tile for its depth
    tiles = np.full((rows * (ny + label + gap), cols * (nx + gap)), np.nan)
    depths = recon.depths
    corners = []
    for k, index in enumerate(chosen):
        r, c = divmod(k, cols)
        y0 = (rows - 1 - r) * (ny + label + gap)
        x0 = c * (nx + gap)
        tiles[y0:y0 + ny, x0:x0 + nx] = amp[index] / peak
        corners.append((x0 + nx / 2, y0 + ny + label / 2, f"z = {depths[index]:.3f} m"))
    width, height = 2.1 * cols + 1.3, 2.3 * rows + 0.5
    fig = Figure(figsize=(width, height))
    suptitle = (f"{plain_title(name)}: {chosen.size} depth slices of {depths.size} "
                f"({_range_text(recon)}); x right, y up, as the front view\n{plain_title(title)}")
    top = 1 - (_text_inches(suptitle, 8) + 0.15) / height
    ax = fig.add_axes((0.1 / width, 0.1 / height, (width - 1.2) / width, top - 0.1 / height))
    image = ax.imshow(tiles, origin="lower", cmap=_blank_bad("hot"), vmin=0, vmax=1,
                      interpolation="nearest")
    for x, y, text in corners:
        ax.text(x, y, text, ha="center", va="center", fontsize=8)
    ax.set_axis_off()
    cax = fig.add_axes(((width - 0.95) / width, 0.25 / height, 0.12 / width,
                        top - 0.4 / height))
    fig.colorbar(image, cax=cax, label="amplitude / the volume's maximum")
    fig.suptitle(suptitle, fontsize=8, y=1 - 0.05 / height, va="top")
    return fig


def _blank_bad(name: str) -> Colormap:
    """The colour map ``name`` with NaN drawn white (the gaps between tiles)."""
    from matplotlib import colormaps

    return colormaps[name].with_extremes(bad="white")


def time_profile_figure(capture: Capture, depth_range: tuple[float, float],
                        title: str) -> Figure:
    """The capture's time profile (:func:`time_profile`), with the optical paths of the
    depth range the planes span (:func:`round_trip_path`) shaded."""
    path, counts = time_profile(capture)
    near, far = round_trip_path(capture, np.asarray(depth_range))
    width, height = 8.0, 3.8
    fig = Figure(figsize=(width, height))
    heading = ("time profile of the capture (histograms summed over the wall)\n"
               + plain_title(title))
    top = 1 - (_text_inches(heading, 9) + 0.6) / height      # the time axis above the plot
    ax = fig.add_axes((1.0 / width, 0.55 / height, (width - 1.2) / width,
                       top - 0.55 / height))
    ax.plot(path, counts, lw=0.9, color="C0")
    ax.axvspan(float(near), float(far), color="C1", alpha=0.2,
               label=f"the planes' depths {depth_range[0]:.3f}-{depth_range[1]:.3f} m "
                     "(round trip)")
    ax.set_yscale("symlog", linthresh=max(float(np.max(counts)) * 1e-4, 1e-12))
    ax.set_xlabel("optical path (m)")
    ax.set_ylabel("sum over the wall")
    top_axis = ax.secondary_xaxis("top", functions=(_path_to_ns, _ns_to_path))
    top_axis.set_xlabel("time (ns)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.suptitle(heading, fontsize=9, y=1 - 0.05 / height, va="top")
    return fig


def _path_to_ns(path: ArrayLike) -> np.ndarray:
    return np.asarray(path, dtype=np.float64) / _C_M_PER_NS


def _ns_to_path(ns: ArrayLike) -> np.ndarray:
    return np.asarray(ns, dtype=np.float64) * _C_M_PER_NS

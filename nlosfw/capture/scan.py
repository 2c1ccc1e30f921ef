"""Confocal scans stored as MATLAB arrays: how their axes map to the wall's x and y.

The Stanford LCT and f-k files store a confocal scan as a MATLAB array ``[i, j, t]``
without coordinates: the scanned square and the order of its axes are conventions of
the authors' code. A :class:`ScanLayout` states one such convention (which MATLAB axis
runs along x, and whether x or y decreases as the index grows) so the readers, the
per-pixel delay files (``tofgrid``) of the same scan and the tests all use the same one.
A capture read this way keeps its layout in ``scene_info["scan_layout"]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import GridFormat, HFormat
from nlosfw.common.errors import DataError


class ScanLayoutDict(TypedDict):
    """A :class:`ScanLayout` as plain values."""

    x_axis: int
    x_reversed: bool
    y_reversed: bool


@dataclass(frozen=True)
class ScanLayout:
    """Where a MATLAB scan array's first two axes ``(i, j)`` lie on the wall."""

    x_axis: int
    """The MATLAB axis (0 or 1) that runs along x; the other runs along y."""
    x_reversed: bool
    """Whether x decreases as that axis's index grows."""
    y_reversed: bool
    """Whether y decreases as the other axis's index grows."""

    def to_xy(self, array: np.ndarray) -> np.ndarray:
        """A MATLAB-order array ``[i, j, ...]`` as ``[x, y, ...]`` with x and y ascending
        (a view)."""
        xy = array if self.x_axis == 0 else np.swapaxes(array, 0, 1)
        if self.x_reversed:
            xy = xy[::-1]
        if self.y_reversed:
            xy = xy[:, ::-1]
        return xy

    def to_dict(self) -> ScanLayoutDict:
        """Plain values for ``scene_info["scan_layout"]``."""
        return {"x_axis": self.x_axis, "x_reversed": self.x_reversed,
                "y_reversed": self.y_reversed}

    @classmethod
    def of(cls, capture: Capture) -> ScanLayout | None:
        """The layout a reader recorded in ``capture.scene_info`` (None: no MATLAB scan)."""
        data = capture.scene_info.get("scan_layout")
        if not isinstance(data, dict):
            return None
        try:
            return cls(int(data["x_axis"]), bool(data["x_reversed"]), bool(data["y_reversed"]))
        except (KeyError, TypeError, ValueError):
            return None


def square_scan_grid(n: int, half_width: float) -> np.ndarray:
    """``n`` x ``n`` cell-centred points on the wall z = 0 spanning x, y in
    [-half_width, half_width]: shape (X, Y, 3), x and y ascending, spacing 2 half_width / n."""
    coords = -half_width + (np.arange(n) + 0.5) * (2.0 * half_width / n)
    x, y = np.meshgrid(coords, coords, indexing="ij")
    return np.stack([x, y, np.zeros_like(x)], axis=-1)


@dataclass(frozen=True)
class ConfocalScan:
    """A confocal scan of a square of half-width ``half_width`` (m), time zero at the wall."""

    histograms: np.ndarray
    """The MATLAB array ``[i, j, t]`` as read (any numeric type)."""
    layout: ScanLayout
    half_width: float
    delta_t: float
    """Bin width in metres of optical path."""
    scene_info: dict[str, Any]


def confocal_capture(scan: ConfocalScan) -> Capture:
    """The capture of a confocal square scan: H (T, X, Y) float32 on the layout's grid,
    t_start 0, no device legs in the time axis, laser and sensor on the same points."""
    hist = scan.histograms
    if hist.ndim != 3 or hist.shape[0] != hist.shape[1] or hist.shape[0] < 1:
        raise DataError(f"the scan must be a square grid [N, N, T], got shape "
                        f"{list(hist.shape)}")
    if hist.shape[0] < 2 or hist.shape[2] < 2:
        raise DataError(f"the scan has shape {list(hist.shape)}; at least 2 x 2 points of 2 "
                        "bins are needed to image anything")
    if not np.issubdtype(hist.dtype, np.number) or np.iscomplexobj(hist):
        raise DataError(f"the histograms must be real numbers, got {hist.dtype}")
    # a view where the file's order allows it: a full f-k scan is 2 GB in float32
    H = np.asarray(np.moveaxis(scan.layout.to_xy(hist), 2, 0), dtype=np.float32)
    grid = square_scan_grid(hist.shape[0], scan.half_width)
    normals = np.zeros_like(grid)
    normals[..., 2] = 1.0
    info = {**scan.scene_info, "scan_layout": scan.layout.to_dict()}
    return Capture(H=H, H_format=HFormat.T_Sx_Sy, sensor_grid_xyz=grid, laser_grid_xyz=grid,
                   sensor_grid_normals=normals, laser_grid_normals=normals,
                   sensor_grid_format=GridFormat.X_Y_3, laser_grid_format=GridFormat.X_Y_3,
                   delta_t=scan.delta_t, t_start=0.0, t_accounts_first_and_last_bounces=False,
                   scene_info=info)


def on_scan_grid(capture: Capture, values: np.ndarray) -> np.ndarray:
    """Per-scan-point ``values`` in the MATLAB order ``[i, j]`` of the file ``capture`` was
    read from, as (X, Y) on its grid (as they are when it records no layout)."""
    layout = ScanLayout.of(capture)
    return np.asarray(values) if layout is None else layout.to_xy(np.asarray(values))

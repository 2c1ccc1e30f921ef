"""Preprocessing of a capture's scan grid: flip, transpose, bin, stride, and a listed set
of wall points recognised as a grid; pure functions, each returning a new capture."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat
from nlosfw.capture.preprocess_options import FlipAxes
from nlosfw.common.errors import ConfigError

#: A map of wall points or directions (..., 3) to new ones.
PointMap = Callable[[np.ndarray], np.ndarray]


def _two_points_left(capture: Capture, k: int, option: str) -> None:
    nx, ny = capture.grid_shape
    if k >= min(nx, ny):
        raise ConfigError(option, f"{k} leaves fewer than 2 x 2 points of the {nx}x{ny} scan "
                                  f"grid; valid: 1 to {max(min(nx, ny) - 1, 1)}")


def _need_grid(capture: Capture, option: str) -> None:
    if capture.H_format is not HFormat.T_Sx_Sy or capture.sensor_grid_format is not \
            GridFormat.X_Y_3:
        raise ConfigError(option, f"needs a capture on a scan grid (T_Sx_Sy, X_Y_3), got "
                                  f"{capture.H_format.name} with {capture.sensor_grid_format.name}")


def _regular_centre(capture: Capture, option: str) -> np.ndarray:
    """The centre (3,) of an axis-aligned regular scan grid in the plane z = 0."""
    _need_grid(capture, option)
    grid = capture.sensor_grid_xyz
    xs, ys = grid[:, 0, 0], grid[0, :, 1]
    expected = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
    if not (np.allclose(grid[..., :2], expected, atol=1e-6) and np.allclose(grid[..., 2], 0,
                                                                          atol=1e-6)):
        raise ConfigError(option, "needs an axis-aligned scan grid in the wall plane z = 0")
    return np.array([(xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2, 0.0])


def _map_points(capture: Capture, fn: PointMap, fn_dir: PointMap) -> dict[str, np.ndarray | None]:
    """The laser point, devices and normals of ``capture`` with a point map ``fn`` and a
    direction map ``fn_dir`` applied (the sensor grid is handled by the caller)."""
    changes: dict[str, np.ndarray | None] = {}
    for name in ("sensor_xyz", "laser_xyz"):
        value = getattr(capture, name)
        if value is not None:
            changes[name] = fn(value)
    if capture.kind is CaptureKind.SINGLE_SPOT:
        changes["laser_grid_xyz"] = fn(capture.laser_grid_xyz)
        if capture.laser_grid_normals is not None:
            changes["laser_grid_normals"] = fn_dir(capture.laser_grid_normals)
    return changes


def _with_grid(capture: Capture, H: np.ndarray, grid: np.ndarray, normals: np.ndarray | None,
               changes: dict[str, np.ndarray | None]) -> Capture:
    if capture.kind is CaptureKind.CONFOCAL:
        changes["laser_grid_xyz"] = grid
        changes["laser_grid_normals"] = normals
    return capture.replace(H=np.ascontiguousarray(H), sensor_grid_xyz=grid,
                           sensor_grid_normals=normals, **changes)


def flip_scan(capture: Capture, axes: FlipAxes, option: str = "capture.flip") -> Capture:
    """Mirror the scan about its centre line(s): the data of each point moves to its mirror
    point, and the laser point and devices are mirrored with it (a physical mirror image)."""
    centre = _regular_centre(capture, option)
    dims = [d for d, name in ((0, "x"), (1, "y")) if name in axes.value]
    sign = np.ones(3)
    sign[dims] = -1

    def point(p: np.ndarray) -> np.ndarray:
        return centre + (np.asarray(p) - centre) * sign

    def direction(v: np.ndarray) -> np.ndarray:
        return np.asarray(v) * sign

    H = capture.H
    grid = capture.sensor_grid_xyz
    normals = capture.sensor_grid_normals
    for d in dims:  # mirror the points, then reverse the axis: the grid stays ascending
        H = np.flip(H, axis=1 + d)
        grid = np.flip(grid, axis=d)
        normals = None if normals is None else np.flip(normals, axis=d)
    return _with_grid(capture, H.copy(), point(grid), None if normals is None
                      else direction(normals), _map_points(capture, point, direction))


def transpose_scan(capture: Capture, option: str = "capture.transpose") -> Capture:
    """Swap the scan axes: a mirror about the grid's diagonal through its centre
    ((x, y) -> (y, x) relative to the centre), data, laser point and devices with it."""
    centre = _regular_centre(capture, option)

    def point(p: np.ndarray) -> np.ndarray:
        q = np.asarray(p) - centre
        return centre + q[..., [1, 0, 2]]

    def direction(v: np.ndarray) -> np.ndarray:
        return np.asarray(v)[..., [1, 0, 2]]

    H = np.swapaxes(capture.H, 1, 2).copy()
    grid = point(np.swapaxes(capture.sensor_grid_xyz, 0, 1))
    normals = capture.sensor_grid_normals
    normals = None if normals is None else direction(np.swapaxes(normals, 0, 1))
    return _with_grid(capture, H, grid, normals, _map_points(capture, point, direction))


def bin_scan(capture: Capture, k: int, option: str = "capture.bin") -> Capture:
    """Sum each k x k block of scan points into one, at the block's mean position."""
    _need_grid(capture, option)
    _two_points_left(capture, k, option)
    nx, ny = capture.grid_shape
    if nx % k or ny % k:
        raise ConfigError(option, f"{k} does not divide the scan grid {nx}x{ny}; valid: a "
                                  "common divisor of both sides")
    T = capture.n_bins
    H = capture.H.reshape(T, nx // k, k, ny // k, k).sum(axis=(2, 4))
    grid = capture.sensor_grid_xyz.reshape(nx // k, k, ny // k, k, 3).mean(axis=(1, 3))
    normals = capture.sensor_grid_normals
    if normals is not None:
        normals = normals.reshape(nx // k, k, ny // k, k, 3).mean(axis=(1, 3))
        normals = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return _with_grid(capture, H, grid, normals, {})


def stride_scan(capture: Capture, k: int, option: str = "capture.stride") -> Capture:
    """Every k-th scan point in x and in y (from the first)."""
    _need_grid(capture, option)
    _two_points_left(capture, k, option)
    H = capture.H[:, ::k, ::k].copy()
    grid = capture.sensor_grid_xyz[::k, ::k].copy()
    normals = capture.sensor_grid_normals
    normals = None if normals is None else normals[::k, ::k].copy()
    return _with_grid(capture, H, grid, normals, {})


def as_scan_grid(capture: Capture, rtol: float = 0.05) -> Capture | None:
    """A capture whose sensors are a list (T_Si, N_3) forming a complete, regular,
    axis-aligned grid in the wall plane z = 0, as that grid (T_Sx_Sy, X_Y_3, x and y
    ascending); None for any other capture. ``rtol``: tolerance on the positions, as a
    fraction of the grid spacing."""
    if capture.H_format is not HFormat.T_Si or capture.kind is CaptureKind.EXHAUSTIVE:
        return None
    pts = capture.sensor_points
    if pts.shape[0] < 4:
        return None
    axes = []
    for d in (0, 1):
        values = np.sort(pts[:, d])
        gaps = np.diff(values)
        step = float(gaps.max()) if gaps.size else 0.0
        if step <= 0:
            return None
        starts = np.concatenate([[0], np.flatnonzero(gaps > rtol * step) + 1])
        centres = np.array([values[a:b].mean() for a, b in
                            zip(starts, [*starts[1:], values.size], strict=True)])
        if centres.size > 1:
            spacing = np.diff(centres)
            if not np.allclose(spacing, spacing.mean(), rtol=rtol, atol=0):
                return None
        axes.append(centres)
    xs, ys = axes
    if xs.size * ys.size != pts.shape[0] or xs.size < 2 or ys.size < 2:
        return None
    dx, dy = float(xs[1] - xs[0]), float(ys[1] - ys[0])
    if np.abs(pts[:, 2]).max() > rtol * min(dx, dy):
        return None
    ix = np.rint((pts[:, 0] - xs[0]) / dx).astype(int)
    iy = np.rint((pts[:, 1] - ys[0]) / dy).astype(int)
    slot = ix * ys.size + iy
    if np.unique(slot).size != slot.size:
        return None
    order = np.argsort(slot)
    shape = (xs.size, ys.size)
    H = np.ascontiguousarray(capture.H.reshape(capture.n_bins, -1)[:, order]).reshape(
        capture.n_bins, *shape)
    grid = pts[order].reshape(*shape, 3)
    normals = capture.sensor_grid_normals
    normals = None if normals is None else normals.reshape(-1, 3)[order].reshape(*shape, 3)
    changes: dict[str, np.ndarray | GridFormat | None] = {}
    if capture.kind is CaptureKind.CONFOCAL:
        changes = {"laser_grid_xyz": grid, "laser_grid_normals": normals,
                   "laser_grid_format": GridFormat.X_Y_3}
    return capture.replace(H=H, H_format=HFormat.T_Sx_Sy, sensor_grid_xyz=grid,
                           sensor_grid_normals=normals, sensor_grid_format=GridFormat.X_Y_3,
                           **changes)

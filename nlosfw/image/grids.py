"""Regular wall and voxel grids: orientation, spacing, flatness (shared by the plane imagers).

A grid (Y, X, 3) is *canonical* when x runs along axis 1 and y along axis 0, both
increasing; :func:`grid_ops` finds the transpose and flips that make one so,
:func:`apply_ops` applies them and :func:`undo_ops` reverts them.
"""

from __future__ import annotations

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.transform.field import PhasorField, regular_grid_spacing

#: Relative tolerance on plane flatness.
RTOL = 1e-6

GridOps = tuple[bool, bool, bool]


def grid_ops(points: np.ndarray) -> GridOps:
    """(transpose, flip rows, flip columns) that make x run along axis 1 and y along axis 0,
    both increasing (a single row or column is oriented by its one varying coordinate)."""
    p = points
    transpose = False
    if p.shape[0] > 1 and p.shape[1] > 1:
        along0 = np.abs(p[1, 0, :2] - p[0, 0, :2])
        transpose = bool(along0[0] > along0[1])
    elif p.shape[0] > 1:
        transpose = bool(abs(p[1, 0, 0] - p[0, 0, 0]) > abs(p[1, 0, 1] - p[0, 0, 1]))
    elif p.shape[1] > 1:
        transpose = bool(abs(p[0, 1, 1] - p[0, 0, 1]) > abs(p[0, 1, 0] - p[0, 0, 0]))
    q = p.transpose(1, 0, 2) if transpose else p
    flip_rows = q.shape[0] > 1 and q[-1, 0, 1] < q[0, 0, 1]
    flip_cols = q.shape[1] > 1 and q[0, -1, 0] < q[0, 0, 0]
    return transpose, bool(flip_rows), bool(flip_cols)


def apply_ops(a: np.ndarray, ops: GridOps, axes: tuple[int, int]) -> np.ndarray:
    """Bring an array laid out like the grid into canonical order."""
    transpose, flip_rows, flip_cols = ops
    if transpose:
        a = np.swapaxes(a, *axes)
    if flip_rows:
        a = np.flip(a, axis=axes[0])
    if flip_cols:
        a = np.flip(a, axis=axes[1])
    return a


def undo_ops(a: np.ndarray, ops: GridOps, axes: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`apply_ops`."""
    transpose, flip_rows, flip_cols = ops
    if flip_cols:
        a = np.flip(a, axis=axes[1])
    if flip_rows:
        a = np.flip(a, axis=axes[0])
    if transpose:
        a = np.swapaxes(a, *axes)
    return a


def wall_grid(field: PhasorField) -> tuple[GridOps, tuple[float, float],
                                            tuple[float, float]]:
    """(ops, (y0, x0), (dy, dx)) of the field's wall in canonical order; DataError if irregular."""
    wall = field.wall_xyz
    ops = grid_ops(wall)
    canon = apply_ops(wall, ops, axes=(0, 1))
    spacing = regular_grid_spacing(canon)
    if spacing is None:
        raise DataError("field.wall_xyz: the imager needs the field on a regular, "
                        "axis-aligned wall grid in the plane z = 0; use the rsd imager for "
                        "other walls")
    return ops, (float(canon[0, 0, 1]), float(canon[0, 0, 0])), spacing


def plane_grid(plane: np.ndarray, index: int) -> tuple[GridOps,
                                                         tuple[float, float],
                                                         tuple[float, float], float]:
    """(ops, (y0, x0), (dy, dx), z) of one voxel plane; DataError unless it is a regular grid
    parallel to the wall."""
    z = plane[..., 2]
    scale = max(1.0, float(np.abs(z).max()), float(np.ptp(plane[..., :2])))
    if np.ptp(z) > RTOL * scale:
        raise DataError(f"voxels: plane {index} is not parallel to the wall (z from "
                        f"{z.min():.6g} to {z.max():.6g} m); the imager needs planes of "
                        "constant z on a regular x-y grid; use the rsd imager for other voxels")
    flat = plane.copy()
    flat[..., 2] = 0.0
    ops = grid_ops(flat)
    canon = apply_ops(flat, ops, axes=(0, 1))
    spacing = regular_grid_spacing(canon)
    if spacing is None:
        raise DataError(f"voxels: plane {index} is not a regular axis-aligned x-y grid; the fft "
                        "imager needs regularly spaced planes parallel to the wall; use the rsd "
                        "imager for other voxels")
    return ops, (float(canon[0, 0, 1]), float(canon[0, 0, 0])), spacing, float(z.mean())

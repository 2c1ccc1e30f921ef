"""The field conversion of the Zaragoza NLOS dataset's HDF5 files to y-tal's, as y-tal does
it (``tal/io/format.py``, ``__convert_dict_znlos_to_tal``); see :mod:`nlosfw.capture.znlos`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from nlosfw.capture.enums import GridFormat, HFormat, VolumeFormat
from nlosfw.common.errors import DataError


def _xy3(arr: npt.ArrayLike) -> np.ndarray:
    """ZNLOS stores point grids as (3, ...) (MATLAB order); y-tal fully transposes them."""
    arr = np.asarray(arr, dtype=np.float64)
    return np.transpose(arr) if arr.shape[0] == 3 else arr


def data_order(shape: tuple[int, ...]) -> tuple[int, ...] | None:
    """Where each axis of a ZNLOS ``data`` array goes (``np.moveaxis`` destinations) to
    read (colors, bounces, t, *space); None for an order y-tal does not know."""
    if len(shape) == 7:
        if shape[4] == 6:  # (ly, lx, sy, sx, bounces, t, colors)
            return (4, 3, 6, 5, 1, 2, 0)
        if shape[2] == 6:  # (colors, t, bounces, sx, sy, lx, ly)
            return (0, 2, 1, 6, 5, 4, 3)
    elif len(shape) == 5:
        if shape[0] == shape[1]:  # (sy, sx, bounces, t, colors)
            return (3, 4, 1, 2, 0)
        if shape[3] == shape[4]:  # (colors, t, bounces, sx, sy)
            return (0, 2, 1, 4, 3)
    return None


def data_transient_shape(shape: tuple[int, ...]) -> tuple[int, int, int] | None:
    """(time bins, sensor points, laser points) of a ZNLOS ``data`` array of ``shape``."""
    order = data_order(shape)
    if order is None:
        return None
    canonical = [0] * len(shape)
    for axis, destination in enumerate(order):
        canonical[destination] = int(shape[axis])
    space = canonical[3:]                  # (sy, sx) or (lx, ly, sx, sy)
    if len(space) == 2:
        return canonical[2], space[0] * space[1], 1
    return canonical[2], space[2] * space[3], space[0] * space[1]


def znlos_to_ytal(raw: dict[str, Any], path: Path) -> dict[str, Any]:
    """Convert a Zaragoza NLOS dataset file's fields to y-tal's, as y-tal does."""
    needed = ("data", "deltaT", "t0", "cameraPosition", "cameraGridPositions",
              "laserPosition", "laserGridPositions")
    missing = [k for k in needed if raw.get(k) is None]
    if missing:
        raise DataError(f"{path}: Zaragoza (HDF5_ZNLOS) file lacks field '{missing[0]}'")
    H = np.asarray(raw["data"])
    if H.ndim not in (5, 7):
        raise DataError(f"{path}: field 'data' must have 5 (confocal) or 7 axes, got {H.ndim}")
    order = data_order(H.shape)
    if order is None:
        raise DataError(f"{path}: field 'data' has {H.ndim} axes {H.shape} in no known ZNLOS "
                        "order")
    H = np.squeeze(np.moveaxis(H, list(range(H.ndim)), order).sum(axis=(0, 1)))
    if H.ndim not in (3, 5):
        raise DataError(f"{path}: field 'data' reduces to {H.ndim} axes; expected 3 or 5")

    def opt(key: str) -> np.ndarray | None:
        return None if raw.get(key) is None else _xy3(raw[key])

    volume = {}
    for src, dst in (("hiddenVolumePosition", "center"), ("hiddenVolumeRotation", "rotation"),
                     ("hiddenVolumeSize", "size")):
        if raw.get(src) is not None:
            v = np.asarray(raw[src], dtype=float).reshape(-1)
            volume[dst] = (np.repeat(v, 3) if v.size == 1 else v).tolist()
    return {
        "H": H.astype(np.float32),
        "H_format": HFormat.T_Sx_Sy if H.ndim == 3 else HFormat.T_Lx_Ly_Sx_Sy,
        "sensor_xyz": np.asarray(raw["cameraPosition"], dtype=float).reshape(3),
        "sensor_grid_xyz": _xy3(raw["cameraGridPositions"]),
        "sensor_grid_normals": opt("cameraGridNormals"),
        "sensor_grid_format": GridFormat.X_Y_3,
        "laser_xyz": np.asarray(raw["laserPosition"], dtype=float).reshape(3),
        "laser_grid_xyz": _xy3(raw["laserGridPositions"]),
        "laser_grid_normals": opt("laserGridNormals"),
        "laser_grid_format": GridFormat.X_Y_3,
        "volume_format": VolumeFormat.X_Y_Z_3,
        "delta_t": raw["deltaT"],
        "t_start": raw["t0"],
        "t_accounts_first_and_last_bounces": True,
        "scene_info": {"original_format": "HDF5_ZNLOS", "volume": volume},
    }

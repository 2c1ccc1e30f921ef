"""The field conversion of the Zaragoza NLOS dataset's HDF5 files to y-tal's, as y-tal does
it (``tal/io/format.py``, ``__convert_dict_znlos_to_tal``); see :mod:`nlosfw.capture.znlos`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from nlosfw.capture.enums import GridFormat, HFormat, VolumeFormat
from nlosfw.common.errors import DataError


def _xy3(arr: Any) -> np.ndarray:
    """ZNLOS stores point grids as (3, ...) (MATLAB order); y-tal fully transposes them."""
    arr = np.asarray(arr, dtype=np.float64)
    return np.transpose(arr) if arr.shape[0] == 3 else arr


def znlos_to_ytal(raw: dict[str, Any], path: Path) -> dict[str, Any]:
    """Convert a Zaragoza NLOS dataset file's fields to y-tal's, as y-tal does."""
    needed = ("data", "deltaT", "t0", "cameraPosition", "cameraGridPositions",
              "laserPosition", "laserGridPositions")
    missing = [k for k in needed if raw.get(k) is None]
    if missing:
        raise DataError(f"{path}: Zaragoza (HDF5_ZNLOS) file lacks field '{missing[0]}'")
    H = np.asarray(raw["data"])
    if H.ndim == 7:
        if H.shape[4] == 6:  # (ly, lx, sy, sx, bounces, t, colors)
            H = np.moveaxis(H, list(range(7)), (4, 3, 6, 5, 1, 2, 0))
        elif H.shape[2] == 6:  # (colors, t, bounces, sx, sy, lx, ly)
            H = np.moveaxis(H, list(range(7)), (0, 2, 1, 6, 5, 4, 3))
        else:
            raise DataError(f"{path}: field 'data' has 7 axes {H.shape} in no known ZNLOS order")
    elif H.ndim == 5:
        if H.shape[0] == H.shape[1]:  # (sy, sx, bounces, t, colors)
            H = np.moveaxis(H, list(range(5)), (3, 4, 1, 2, 0))
        elif H.shape[3] == H.shape[4]:  # (colors, t, bounces, sx, sy)
            H = np.moveaxis(H, list(range(5)), (0, 2, 1, 4, 3))
        else:
            raise DataError(f"{path}: field 'data' has 5 axes {H.shape} in no known ZNLOS order")
    else:
        raise DataError(f"{path}: field 'data' must have 5 (confocal) or 7 axes, got {H.ndim}")
    H = np.squeeze(H.sum(axis=(0, 1)))
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

"""Captures as HDF5 files in y-tal's layout (and reading the Zaragoza NLOS dataset's).

One top-level dataset per :class:`~nlosfw.capture.Capture` field, enums as HDF5
enum datasets of shape (1,), ``None`` as an empty dataset, ``scene_info`` as a
YAML string. A file written here holds exactly y-tal's keys, so
``tal.io.read_capture`` opens it unchanged.
"""

from __future__ import annotations

import logging
from enum import IntEnum
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from nlosfw.capture.data import YTAL_FIELDS, Capture
from nlosfw.capture.enums import GridFormat, HFormat, VolumeFormat
from nlosfw.common import yaml_safe
from nlosfw.common.errors import DataError, one_line
from nlosfw.common.hdf5 import new_file

log = logging.getLogger(__name__)

_ENUMS: dict[str, type[IntEnum]] = {
    "H_format": HFormat,
    "sensor_grid_format": GridFormat,
    "laser_grid_format": GridFormat,
    "volume_format": VolumeFormat,
}
# y-tal 0.20 knows only these members; writing the same enum mapping keeps files identical.
_YTAL_ENUM_MEMBERS = {
    HFormat: ("UNKNOWN", "T_Sx_Sy", "T_Lx_Ly_Sx_Sy", "T_Si", "T_Li_Si"),
    GridFormat: ("UNKNOWN", "N_3", "X_Y_3"),
    VolumeFormat: ("UNKNOWN", "N_3", "X_Y_Z_3", "X_Y_3"),
}
_REQUIRED = ("H", "H_format", "sensor_grid_xyz", "laser_grid_xyz", "delta_t")


def write_capture(path: str | Path, capture: Capture, compression: int = 0,
                  overwrite: bool = False) -> Path:
    """Write ``capture`` atomically to ``path`` in y-tal's HDF5 layout.

    ``compression`` is a gzip level 0-9 for ``H`` (0: none). An existing file is
    never replaced unless ``overwrite``.
    """
    if not 0 <= compression <= 9:
        raise DataError(f"compression: must be a gzip level 0-9, got {compression}")
    with new_file(path, overwrite=overwrite) as f:
        for key in YTAL_FIELDS:
            _write_field(f, key, getattr(capture, key), compression)
    return Path(path)


def read_capture(path: str | Path) -> Capture:
    """Read a capture written by nlosfw or y-tal, or a Zaragoza dataset (HDF5_ZNLOS) file.

    Every problem (not HDF5, truncated, missing or malformed field, NaN in H,
    mismatched grids) raises :class:`DataError` naming the file and the field.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: capture file not found")
    try:
        with h5py.File(path, "r") as f:
            raw = {key: _read_field(f, key, path) for key in f}
    except DataError:
        raise
    except (OSError, RuntimeError, ValueError, KeyError) as err:
        raise DataError(f"{path}: not a readable HDF5 capture ({one_line(err)})") from None
    if "data" in raw and "H" not in raw:
        raw = _znlos_to_ytal(raw, path)
    missing = [k for k in _REQUIRED if raw.get(k) is None]
    if missing:
        raise DataError(f"{path}: missing field '{missing[0]}' (a y-tal capture needs "
                        f"{', '.join(_REQUIRED)})")
    unknown = sorted(set(raw) - set(YTAL_FIELDS))
    if unknown:
        log.warning("%s: ignoring fields unknown to y-tal's format: %s", path, ", ".join(unknown))
    kwargs: dict[str, Any] = {}
    for key in YTAL_FIELDS:
        value = raw.get(key)
        if value is None:
            continue
        if key in _ENUMS:
            try:
                value = _ENUMS[key](int(np.asarray(value).reshape(-1)[0]))
            except (ValueError, IndexError):
                valid = ", ".join(f"{m.name}={m.value}" for m in _ENUMS[key])
                raise DataError(f"{path}: field '{key}' has invalid value {value!r}; "
                                f"valid: {valid}") from None
        elif key in ("delta_t", "t_start"):
            value = _scalar(value, key, path)
        elif key == "t_accounts_first_and_last_bounces":
            value = bool(np.asarray(value).reshape(-1)[0])
        elif key == "scene_info":
            value = _scene_info(value, path)
        kwargs[key] = value
    if kwargs.get("sensor_grid_normals") is None and "sensor_grid_xyz" in kwargs:
        log.info("%s: no sensor_grid_normals; assuming +z", path)
    try:
        return Capture(**kwargs)
    except DataError as err:
        raise DataError(f"{path}: {err}") from None
    except TypeError as err:
        raise DataError(f"{path}: malformed capture ({err})") from None


def _write_field(f: h5py.File, key: str, value: Any, compression: int) -> None:
    if value is None:
        f.create_dataset(key, data=h5py.Empty("f8"))
    elif key in _ENUMS:
        enum_cls = _ENUMS[key]
        names = _YTAL_ENUM_MEMBERS[enum_cls]
        if value.name not in names:
            names = tuple(m.name for m in enum_cls)
        dt = h5py.enum_dtype({n: enum_cls[n].value for n in names}, basetype="i")
        ds = f.create_dataset(key, (1,), dtype=dt)
        ds[0] = int(value)
    elif key == "scene_info":
        f.create_dataset(key, data=yaml_safe.dump(value or {}),
                         dtype=h5py.string_dtype(encoding="utf-8"))
    elif key == "H" and compression > 0:
        f.create_dataset(key, data=value, compression="gzip", compression_opts=compression,
                         chunks=True)
    elif key == "t_accounts_first_and_last_bounces":
        f.create_dataset(key, data=np.bool_(value))
    elif key in ("delta_t", "t_start"):
        f.create_dataset(key, data=np.float64(value))
    else:
        f.create_dataset(key, data=np.asarray(value))


def _read_field(f: h5py.File, key: str, path: Path) -> Any:
    node = f[key]
    if isinstance(node, h5py.Group):  # Zaragoza files keep nothing we need in groups
        return None
    if node.shape is None:  # h5py.Empty: y-tal's None
        return None
    try:
        value = node[()]
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: field '{key}' cannot be read (file truncated or corrupt: "
                        f"{one_line(err)})") from None
    return value


def _scalar(value: Any, key: str, path: Path) -> float:
    arr = np.asarray(value)
    if arr.size != 1 or not np.issubdtype(arr.dtype, np.number):
        raise DataError(f"{path}: field '{key}' must be one number of metres, "
                        f"got shape {arr.shape}")
    return float(arr.reshape(-1)[0])


def _scene_info(value: Any, path: Path) -> dict:
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    if isinstance(value, (bytes, str)):
        try:
            value = yaml_safe.load(value)
        except yaml_safe.LimitExceeded as err:
            raise DataError(f"{path}: field 'scene_info' is refused: {err}") from None
        except Exception as err:  # yaml raises many error types
            raise DataError(f"{path}: field 'scene_info' is not valid YAML ({one_line(err)})"
                            ) from None
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise DataError(f"{path}: field 'scene_info' must be a YAML mapping, got "
                        f"{type(value).__name__}")
    return value


# ------------------------------------------------------------------------ Zaragoza (ZNLOS)
def _xy3(arr: Any) -> np.ndarray:
    """ZNLOS stores point grids as (3, ...) (MATLAB order); y-tal fully transposes them."""
    arr = np.asarray(arr, dtype=np.float64)
    return np.transpose(arr) if arr.shape[0] == 3 else arr


def _znlos_to_ytal(raw: dict[str, Any], path: Path) -> dict[str, Any]:
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

"""Captures as HDF5 files in y-tal's layout (and reading the Zaragoza NLOS dataset's).

One top-level dataset per :class:`~nlosfw.capture.Capture` field, enums as HDF5
enum datasets of shape (1,), ``None`` as an empty dataset, ``scene_info`` as a
YAML string. A file written here holds exactly y-tal's keys, so
``tal.io.read_capture`` opens it unchanged; nlosfw's own files add only the root
attributes ``nlosfw_type = "capture"`` and ``format_version`` (y-tal ignores attributes),
which is how the ``nlosfw`` capture format tells them from other y-tal files.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterable
from enum import IntEnum
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import numpy.typing as npt

from nlosfw.capture.data import YTAL_FIELDS, Capture
from nlosfw.capture.dataset_shapes import FIXED, ytal_shapes, znlos_shapes
from nlosfw.capture.enums import GridFormat, HFormat, VolumeFormat
from nlosfw.capture.hints import HINTS_KEY
from nlosfw.common import yaml_safe
from nlosfw.common.errors import ConfigError, DataError, one_line
from nlosfw.common.hdf5 import new_file, write_header
from nlosfw.common.hdf5_guard import (
    Expected,
    check_header,
    is_numeric,
    open_checked,
    read_dataset,
)
from nlosfw.common.inputs import describe_input
from nlosfw.common.text import json_safe

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
#: The Zaragoza (ZNLOS) layout's datasets (:mod:`nlosfw.capture.znlos_layout`).
ZNLOS_FIELDS = ("data", "deltaT", "t0", "cameraPosition", "cameraGridPositions",
                "cameraGridNormals", "laserPosition", "laserGridPositions", "laserGridNormals",
                "hiddenVolumePosition", "hiddenVolumeRotation", "hiddenVolumeSize")
#: Every top-level dataset :func:`read_fields` reads by default.
KNOWN_FIELDS = (*YTAL_FIELDS, *ZNLOS_FIELDS)


#: The ``nlosfw_type`` root attribute of nlosfw's capture files.
NLOSFW_CAPTURE_TYPE = "capture"


def write_capture(path: str | Path, capture: Capture, compression: int = 0,
                  overwrite: bool = False, nlosfw_attributes: bool = True) -> Path:
    """Write ``capture`` atomically to ``path`` in y-tal's HDF5 layout.

    ``compression`` is a gzip level 0-9 for ``H`` (0: none). An existing file is
    never replaced unless ``overwrite``. ``nlosfw_attributes`` marks the file as
    nlosfw's own (root attributes only: the datasets are y-tal's either way).
    """
    path = _path(path)
    if not isinstance(capture, Capture):
        raise ConfigError("capture", f"write_capture needs a Capture, got "
                                     f"{type(capture).__name__}")
    if isinstance(compression, bool) or not isinstance(compression, (int, np.integer)) or \
            not 0 <= compression <= 9:
        raise ConfigError("compression", f"must be a gzip level 0-9, got {compression!r}")
    for option, value in (("overwrite", overwrite), ("nlosfw_attributes", nlosfw_attributes)):
        if not isinstance(value, (bool, np.bool_)):
            raise ConfigError(option, f"must be true or false, got {value!r}")
    with new_file(path, overwrite=overwrite) as f:
        if nlosfw_attributes:
            write_header(f, NLOSFW_CAPTURE_TYPE)
        for key in YTAL_FIELDS:
            _write_field(f, key, _stored(capture, key), compression)
    return Path(path)


def _stored(capture: Capture, key: str) -> object:
    """Field ``key`` of ``capture`` as the file stores it: ``scene_info`` with the imaging
    hints (y-tal's layout has no field of its own for them)."""
    if key != "scene_info" or capture.imaging_hints is None:
        return getattr(capture, key)
    return {**capture.scene_info, HINTS_KEY: capture.imaging_hints.to_dict()}


def read_capture(path: str | Path) -> Capture:
    """Read a capture written by nlosfw or y-tal, or a Zaragoza dataset (HDF5_ZNLOS) file.

    Every problem (not HDF5, truncated, missing or malformed field, NaN in H,
    mismatched grids) raises :class:`DataError` naming the file and the field.
    """
    path = _path(path)
    raw = read_fields(path)
    if "data" in raw and "H" not in raw:
        from nlosfw.capture.znlos_layout import znlos_to_ytal

        raw = znlos_to_ytal(raw, path)
    return capture_from_fields(raw, path)


def _path(path: object) -> Path:
    """A file path given as ``str`` or ``os.PathLike``; a ConfigError naming ``path`` else."""
    if isinstance(path, os.PathLike) or (isinstance(path, str) and path):
        return Path(path)
    raise ConfigError("path", f"expected a path (str or pathlib.Path), got {path!r} "
                              f"({type(path).__name__})")


def read_fields(path: Path, names: Iterable[str] | None = None) -> dict[str, Any]:
    """The top-level datasets ``names`` of an HDF5 file (default: y-tal's and the Zaragoza
    layout's fields; with ``H`` present, y-tal's only), None for empty ones, groups, and
    grids without the transient that sizes them. Nothing else is read: the file is checked
    for links and storage outside it first, then every dataset's declared shape against
    the one its layout defines (:mod:`nlosfw.capture.dataset_shapes`) and its size, all
    before any is read but ``H_format`` (:mod:`nlosfw.common.hdf5_guard`); other datasets
    are named in a warning."""
    describe_input(path, "capture file")
    wanted = set(KNOWN_FIELDS if names is None else names)
    try:
        with open_checked(path, "capture") as f:
            ignored = sorted(key for key in f if key not in wanted)
            if ignored:
                log.warning("%s: ignoring datasets the capture formats do not define: %s",
                            path, ", ".join(ignored[:20]))
            keys = [key for key in f if key in wanted]
            if "H" in keys:          # a y-tal capture: the Zaragoza layout's fields are unused
                keys = [key for key in keys if key not in ZNLOS_FIELDS]
            rules = _expected_shapes(f, keys, path)
            shaped = {key: f[key] for key in keys if _has_data(f[key])}
            for key in sorted(shaped, key=lambda k: k not in ("H", "data")):  # the transient first
                if key in rules:
                    check_header(shaped[key], path, key, rules[key])
            return {key: (_read_field(f, key, path, rules[key]) if key in rules and key in shaped
                          else None) for key in keys}
    except DataError:
        raise
    except (OSError, RuntimeError, ValueError, KeyError) as err:
        raise DataError(f"{path}: not a readable HDF5 capture ({one_line(err)})") from None


def _has_data(node: object) -> bool:
    """Whether ``node`` is a dataset with a shape (not a group, not h5py.Empty)."""
    return isinstance(node, h5py.Dataset) and node.shape is not None


def _expected_shapes(f: h5py.File, keys: list[str], path: Path) -> dict[str, Expected]:
    """The shape each of ``keys`` may declare (:mod:`nlosfw.capture.dataset_shapes`), from the
    headers of ``H`` and ``data`` and the value of ``H_format`` (read first: one number)."""
    rules = dict(FIXED)
    if "H" in keys and _has_data(f["H"]):
        h_format = None
        if "H_format" in keys and _has_data(f["H_format"]):
            value = _read_field(f, "H_format", path, rules["H_format"])
            with contextlib.suppress(ValueError, TypeError, IndexError):
                h_format = HFormat(int(np.asarray(value).reshape(-1)[0]))
        rules.update(ytal_shapes(tuple(f["H"].shape), h_format))
    if "data" in keys and _has_data(f["data"]):
        rules.update(znlos_shapes(tuple(f["data"].shape)))
    return rules


def capture_from_fields(raw: dict[str, Any], path: Path) -> Capture:
    """The capture of y-tal's fields ``raw`` read from ``path`` (named in every error)."""
    missing = [k for k in _REQUIRED if raw.get(k) is None]
    if missing:
        raise DataError(f"{path}: missing field '{missing[0]}' (a y-tal capture needs "
                        f"{', '.join(_REQUIRED)})")
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


def _read_field(f: h5py.File, key: str, path: Path, expected: Expected) -> Any:
    node = f[key]
    if not _has_data(node):  # a group (Zaragoza files keep nothing we need in groups), or
        return None          # h5py.Empty: y-tal's None
    if key != "scene_info" and key not in _ENUMS and not is_numeric(node):
        raise DataError(f"{path}: field '{key}' must be numeric, got {node.dtype} data")
    return read_dataset(node, path, key, expected=expected)


def _scalar(value: npt.ArrayLike, key: str, path: Path) -> float:
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
    value = json_safe(value)
    if not isinstance(value, dict):
        raise DataError(f"{path}: field 'scene_info' must be a YAML mapping, got "
                        f"{type(value).__name__}")
    return value

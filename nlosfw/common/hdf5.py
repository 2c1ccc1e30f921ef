"""Helpers of nlosfw's own HDF5 files (phasor fields, reconstructions).

Each file carries the attributes ``nlosfw_type`` (what it holds) and
``format_version``; metadata is stored as a YAML string.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from nlosfw.common import yaml_safe
from nlosfw.common.errors import DataError

FORMAT_VERSION = 1


def write_header(f: h5py.File, kind: str) -> None:
    f.attrs["nlosfw_type"] = kind
    f.attrs["format_version"] = FORMAT_VERSION


def write_yaml(f: h5py.File, key: str, value: Any) -> None:
    f.create_dataset(key, data=yaml_safe.dump(value), dtype=h5py.string_dtype("utf-8"))


class open_typed:
    """Open an nlosfw HDF5 file of the expected type, turning h5py errors into DataError."""

    def __init__(self, path: str | Path, kind: str) -> None:
        self.path, self.kind = Path(path), kind

    def __enter__(self) -> tuple[h5py.File, Path]:
        if not self.path.is_file():
            raise DataError(f"{self.path}: file not found")
        try:
            self.file = h5py.File(self.path, "r")
        except OSError as err:
            raise DataError(f"{self.path}: not a readable HDF5 file ({err})") from None
        found = self.file.attrs.get("nlosfw_type")
        if isinstance(found, bytes):
            found = found.decode()
        if found != self.kind:
            self.file.close()
            raise DataError(f"{self.path}: holds {found or 'no nlosfw data'}, expected a "
                            f"{self.kind} file")
        return self.file, self.path

    def __exit__(self, *exc: object) -> None:
        self.file.close()


def read_dataset(f: h5py.File, key: str, path: Path) -> np.ndarray:
    if key not in f:
        raise DataError(f"{path}: missing field '{key}'")
    try:
        return f[key][()]
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: field '{key}' cannot be read ({err})") from None


def read_yaml(f: h5py.File, key: str, path: Path) -> dict:
    if key not in f:
        return {}
    raw: Any = read_dataset(f, key, path)
    if not isinstance(raw, (str, bytes)):
        raise DataError(f"{path}: field '{key}' is not a YAML string")
    try:
        value = yaml_safe.load(raw)
    except Exception as err:  # yaml errors
        raise DataError(f"{path}: field '{key}' is not valid YAML ({err})") from None
    return value or {}

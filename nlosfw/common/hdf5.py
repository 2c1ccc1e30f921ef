"""Helpers of nlosfw's own HDF5 files (phasor fields, reconstructions).

Each file carries the attributes ``nlosfw_type`` (what it holds) and
``format_version``; metadata is stored as a YAML string. Every HDF5 file nlosfw writes
(captures too) is built by :func:`new_file`.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from nlosfw.common import yaml_safe
from nlosfw.common.errors import DataError
from nlosfw.common.files import write_bytes
from nlosfw.common.hdf5_guard import check_file, check_size
from nlosfw.common.inputs import describe_input

FORMAT_VERSION = 1


@contextlib.contextmanager
def new_file(path: str | Path, overwrite: bool = False) -> Iterator[h5py.File]:
    """An HDF5 file open for writing, published atomically as ``path`` when the block ends.

    The file is built in memory and its bytes written with plain Python I/O: libhdf5
    cannot recover from a failed write (a full disk) and crashes the process when it later
    frees the file, while here a full disk is found before anything is written (the exact
    size is known) or ends in a one-line :class:`~nlosfw.common.errors.StorageError`, with
    no partial file. The price is the file's size in memory while it is written. An
    existing ``path`` is kept unless ``overwrite``.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise DataError(f"{path}: already exists; refusing to overwrite it")
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        yield f
    view = buffer.getbuffer()
    try:
        write_bytes(path, view, overwrite=overwrite)
    finally:
        view.release()


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
        describe_input(self.path)
        try:
            self.file = h5py.File(self.path, "r")
        except OSError as err:
            raise DataError(f"{self.path}: not a readable HDF5 file ({err})") from None
        try:
            check_file(self.file, self.path)
        except DataError:
            self.file.close()
            raise
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
        node = f[key]
        if isinstance(node, h5py.Dataset):
            check_size(node, path, key)
        return node[()]
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
    except yaml_safe.LimitExceeded as err:
        raise DataError(f"{path}: field '{key}' is refused: {err}") from None
    except Exception as err:  # yaml errors
        raise DataError(f"{path}: field '{key}' is not valid YAML ({err})") from None
    return value or {}

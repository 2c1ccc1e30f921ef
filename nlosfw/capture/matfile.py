"""MATLAB ``.mat`` files, version 5 (scipy) and 7.3 (HDF5, h5py), seen the same way.

Arrays come back in MATLAB's axis order whatever the version: a v7.3 file is HDF5 and
stores an ``[A, B, C]`` MATLAB array as an HDF5 dataset of shape ``(C, B, A)`` (MATLAB is
column-major), so its axes are reversed here. Version 5 files are read with
``scipy.io.loadmat``, which already gives MATLAB's order. Structs (``dataset.data``) are
HDF5 groups in v7.3 files; :func:`read_mat_struct` reads one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from nlosfw.common.errors import DataError, one_line
from nlosfw.common.files import format_bytes
from nlosfw.common.hdf5_guard import (
    ANY_SHAPE,
    Expected,
    check_file,
    dataset_limit,
    is_numeric,
    open_checked,
    read_dataset,
)
from nlosfw.common.inputs import describe_input
from nlosfw.common.reading import binary, hdf5_file, opened

if TYPE_CHECKING:
    import h5py

#: The text every MATLAB 5 and 7.3 file starts with (7.3 files carry it in the HDF5 user block).
MAT_HEADER = b"MATLAB"
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass(frozen=True)
class MatVariable:
    """One top-level variable: its MATLAB shape (``()`` for a struct) and class name."""

    name: str
    shape: tuple[int, ...]
    matlab_class: str


def is_hdf5(path: Path) -> bool:
    """Whether ``path`` holds HDF5 (a MATLAB 7.3 file is HDF5 after a 512-byte user block)."""
    try:
        with binary(path) as f:
            head = f.read(2048 + 8)
    except OSError:
        return False
    return any(head[offset:offset + 8] == _HDF5_SIGNATURE for offset in (0, 512, 1024, 2048))


def mat_version(path: Path) -> int | None:
    """5 or 73 for a MATLAB file of that version, None for anything else."""
    try:
        with binary(path) as f:
            head = f.read(128)
    except OSError:
        return None
    if not head.startswith(MAT_HEADER):
        return None
    if b"7.3" in head[:40] and is_hdf5(path):
        return 73
    if len(head) >= 128 and head[126:128] in (b"IM", b"MI"):
        return 5
    return None


def mat_variables(path: Path) -> dict[str, MatVariable]:
    """The top-level variables of a v5 or v7.3 file (HDF5 without MATLAB's header counts as
    7.3), by name, without reading their data. DataError if it is neither. Listed once
    while :func:`~nlosfw.common.reading.read_once` holds the file."""
    current = opened(path)
    if current is not None:
        return dict(current.memo("mat_variables", lambda: _mat_variables(path)))
    return _mat_variables(path)


def _mat_variables(path: Path) -> dict[str, MatVariable]:
    describe_input(path)
    if is_hdf5(path):
        try:
            with open_checked(path) as f:
                return {name: _hdf5_variable(name, node) for name, node in f.items()
                        if not name.startswith("#")}
        except (OSError, RuntimeError, KeyError) as err:
            raise DataError(f"{path}: an HDF5 file that cannot be read (truncated or "
                            f"corrupt: {one_line(err)})") from None
    if mat_version(path) == 5:
        import scipy.io

        if not _mat5_complete(path):
            raise DataError(f"{path}: not a readable MATLAB file (truncated or corrupt: a "
                            "variable ends past the end of the file)")
        try:
            with binary(path) as f:
                found = scipy.io.whosmat(f)
        except Exception as err:  # scipy raises several types for damaged files
            raise DataError(f"{path}: not a readable MATLAB file (truncated or corrupt: "
                            f"{one_line(err)})") from None
        return {name: MatVariable(name, tuple(int(n) for n in shape), str(cls))
                for name, shape, cls in found}
    raise DataError(f"{path}: not a MATLAB .mat file (version 5 or 7.3) nor HDF5")


def _mat5_complete(path: Path) -> bool:
    """Whether every top-level element of a MATLAB 5 file ends inside the file (a truncated
    file's last one does not; scipy lists the variables before it without complaint)."""
    import struct

    size = path.stat().st_size
    with binary(path) as f:
        head = f.read(128)
        order = "<" if head[126:128] == b"IM" else ">"
        pos = 128
        while pos < size:
            f.seek(pos)
            tag = f.read(8)
            if len(tag) < 8:
                return False
            kind, nbytes = struct.unpack(order + "II", tag)
            end = pos + 8 + nbytes
            if end > size:
                return False
            pos = end + (0 if kind == 15 else -nbytes % 8)   # 15: compressed, no padding
    return True


def _hdf5_variable(name: str, node: h5py.Dataset | h5py.Group) -> MatVariable:
    import h5py

    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(node, h5py.Group):
        return MatVariable(name, (), cls or "struct")
    shape = () if node.shape is None else tuple(int(n) for n in reversed(node.shape))
    return MatVariable(name, shape, cls or str(node.dtype))


def variables_or_none(path: Path) -> dict[str, MatVariable] | None:
    """:func:`mat_variables`, or None for a file that is neither MATLAB nor HDF5 (for
    detection, which must never raise)."""
    try:
        return mat_variables(path)
    except (DataError, OSError):
        return None


def hdf5_keys(path: Path, group: str = "") -> set[str] | None:
    """The names in an HDF5 file's root (or ``group``), None if it is not a readable HDF5
    file or has no such group; never raises (for detection)."""
    if not is_hdf5(path):
        return None
    import h5py

    try:
        with hdf5_file(path) as f:
            check_file(f, path)
            node = f[group] if group else f
            return set(node.keys()) if isinstance(node, h5py.Group) else None
    except (OSError, KeyError, RuntimeError, ValueError, DataError):
        return None


def hdf5_shape(path: Path, name: str) -> tuple[int, ...] | None:
    """The shape of dataset ``name`` in an HDF5 file, as h5py reports it (MATLAB 7.3 files:
    MATLAB's axes reversed); None if it is not a readable HDF5 file with such a dataset.
    Never raises; reads no data."""
    if not is_hdf5(path):
        return None
    import h5py

    try:
        with hdf5_file(path) as f:
            check_file(f, path)
            node = f.get(name)
            if not isinstance(node, h5py.Dataset) or node.shape is None:
                return None
            return tuple(int(n) for n in node.shape)
    except (OSError, KeyError, RuntimeError, ValueError, DataError):
        return None


def scan_shape(path: Path, name: str) -> tuple[int, int, int] | None:
    """(T, N x M, 1): the transient shape of a confocal scan stored as MATLAB variable
    ``name`` [N, M, T] (v5 or v7.3); None when the file has no such 3-D variable."""
    found = (variables_or_none(path) or {}).get(name)
    if found is None or len(found.shape) != 3:
        return None
    n, m, t = found.shape
    return t, n * m, 1


def require_variables(path: Path, names: Sequence[str], expected: str) -> dict[str, MatVariable]:
    """The variables of ``path``; DataError naming the first of ``names`` it lacks and
    ``expected`` (what the format holds) when one is missing."""
    found = mat_variables(path)
    for name in names:
        if name not in found:
            have = ", ".join(sorted(found)) or "none"
            raise DataError(f"{path}: no variable '{name}' (expected {expected}; the file "
                            f"holds: {have})")
    return found


def read_mat_array(path: Path, name: str, dtype: npt.DTypeLike | None = None,
                   expected: Expected = ANY_SHAPE) -> np.ndarray:
    """Variable ``name`` of a v5 or v7.3 file in MATLAB's axis order (``dtype``: convert
    while reading, so a large v7.3 array is never held in two types at once).

    Only numeric arrays are read: text, cell arrays, structs and sparse matrices are refused
    naming the variable and its class, and a complex array is refused where ``dtype`` is
    real (its imaginary part would be lost). The file is checked for data outside it, and
    the variable's declared shape (MATLAB's order) against ``expected`` and its size,
    before it is read (:mod:`nlosfw.common.hdf5_guard`)."""
    if is_hdf5(path):
        import h5py

        try:
            with open_checked(path) as f:
                node = f.get(name)
                if not isinstance(node, h5py.Dataset):
                    raise DataError(f"{path}: variable '{name}' is missing or not an array")
                header = _hdf5_variable(name, node)
                if header.matlab_class in _NOT_NUMERIC or not is_numeric(node):
                    raise DataError(_not_numeric(path, name, header.matlab_class
                                                 or str(node.dtype)))
                _check_complex(path, name, node.dtype, dtype)
                expected.check(header.shape, path, name, "variable")
                value = read_dataset(node, path, name, dtype, expected=ANY_SHAPE)
        except (OSError, RuntimeError) as err:
            raise DataError(f"{path}: variable '{name}' cannot be read (file truncated or "
                            f"corrupt: {one_line(err)})") from None
        return np.asarray(value).T
    import scipy.io

    found = mat_variables(path).get(name)
    if found is None:
        raise DataError(f"{path}: no variable '{name}'")
    if found.matlab_class in _NOT_NUMERIC:
        raise DataError(_not_numeric(path, name, found.matlab_class))
    expected.check(found.shape, path, name, "variable")
    nbytes = int(np.prod(found.shape, dtype=float)) * 16
    limit = dataset_limit()
    if nbytes > limit:
        raise DataError(f"{path}: variable '{name}' declares shape {list(found.shape)} "
                        f"({format_bytes(nbytes)} at most), more than the "
                        f"{format_bytes(limit)} of memory available; refused before "
                        "reading it")
    try:
        with binary(path) as f:
            value = scipy.io.loadmat(f, variable_names=[name])[name]
    except KeyError:
        raise DataError(f"{path}: no variable '{name}'") from None
    except Exception as err:  # scipy raises several types for damaged files
        raise DataError(f"{path}: variable '{name}' cannot be read (truncated or corrupt: "
                        f"{one_line(err)})") from None
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "biufc":
        raise DataError(_not_numeric(path, name, found.matlab_class))
    _check_complex(path, name, value.dtype, dtype)
    return value if dtype is None else value.astype(dtype, copy=False)


#: MATLAB classes that are not numeric arrays.
_NOT_NUMERIC = ("char", "cell", "struct", "sparse", "function_handle", "object", "string")


def _not_numeric(path: Path, name: str, cls: str) -> str:
    return (f"{path}: variable '{name}' must be numeric, got MATLAB class {cls} (a numeric "
            "array: double, single or an integer type)")


def _check_complex(path: Path, name: str, found: npt.DTypeLike,
                   dtype: npt.DTypeLike | None) -> None:
    if np.dtype(found).kind == "c" and dtype is not None and np.dtype(dtype).kind != "c":
        raise DataError(f"{path}: variable '{name}' must be real, got complex numbers")


def mat_struct_shapes(path: Path, name: str) -> dict[str, tuple[int, ...]]:
    """The MATLAB shapes of the array fields of struct ``name`` of a v7.3 file, from their
    headers (no data read); DataError when it has no such struct."""
    import h5py

    if not is_hdf5(path):
        raise DataError(f"{path}: struct '{name}' must be in a MATLAB 7.3 (HDF5) file")
    try:
        with open_checked(path) as f:
            group = _struct(f, name, path)
            return {key: _hdf5_variable(key, node).shape for key, node in group.items()
                    if isinstance(node, h5py.Dataset)}
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: struct '{name}' cannot be read (file truncated or corrupt: "
                        f"{one_line(err)})") from None


def _struct(f: h5py.File, name: str, path: Path) -> h5py.Group:
    import h5py

    group = f.get(name)
    if not isinstance(group, h5py.Group):
        raise DataError(f"{path}: no struct '{name}' (the file holds: "
                        f"{', '.join(sorted(f)) or 'nothing'})")
    return group


def read_mat_struct(path: Path, name: str, fields: Sequence[str] | None = None,
                    expected: Mapping[str, Expected] | None = None) -> dict[str, np.ndarray]:
    """The numeric ``fields`` of struct ``name`` of a v7.3 file that it has (default: all;
    each in MATLAB's axis order); no other field is read. Every field's declared shape is
    checked against ``expected[field]`` (any shape where none is given) before any is read."""
    import h5py

    if not is_hdf5(path):
        raise DataError(f"{path}: struct '{name}' must be in a MATLAB 7.3 (HDF5) file")
    rules = dict(expected or {})
    try:
        with open_checked(path) as f:
            group = _struct(f, name, path)
            nodes = {}
            for key in (list(group) if fields is None else fields):
                node = group.get(key)
                if not isinstance(node, h5py.Dataset):
                    continue
                if not is_numeric(node):
                    raise DataError(_not_numeric(path, f"{name}.{key}", str(node.dtype)))
                rules.get(key, ANY_SHAPE).check(_hdf5_variable(key, node).shape, path,
                                                f"{name}.{key}", "variable")
                nodes[key] = node
            return {key: np.asarray(read_dataset(node, path, f"{name}.{key}",
                                                 expected=ANY_SHAPE)).T
                    for key, node in nodes.items()}
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: struct '{name}' cannot be read (file truncated or corrupt: "
                        f"{one_line(err)})") from None


def scalar(value: np.ndarray, path: Path, name: str, expected: str) -> float:
    """The one finite number ``value`` holds; DataError naming ``name`` and ``expected``."""
    arr = np.asarray(value)
    if arr.size != 1 or not np.issubdtype(arr.dtype, np.number):
        raise DataError(f"{path}: variable '{name}' must be {expected}, got shape {arr.shape} "
                        f"of {arr.dtype}")
    number = float(arr.reshape(-1)[0])
    if not np.isfinite(number):
        raise DataError(f"{path}: variable '{name}' must be {expected}, got {number}")
    return number

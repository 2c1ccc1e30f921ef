"""Reading untrusted HDF5 files (captures, MATLAB 7.3 files) without leaving them.

HDF5 can make a file's dataset read bytes from elsewhere: raw data stored in external
files (``/etc/passwd``), virtual datasets mapping other files, external links, and soft
links through them. A capture is untrusted input, so :func:`open_checked` walks every link
of a file before anything is read and refuses, in one line naming the file and the
dataset, any of those; :func:`read_dataset` checks a dataset's declared shape against the
shapes its reader expects (:class:`Expected`, e.g. as many points as the transient has
sensors) and sizes it (shape × dtype) before reading it, refusing one of another shape, or
larger than :func:`dataset_limit` (the memory this process can still allocate): a tiny
file declaring a huge dataset is refused in one line, from its header, instead of being
read in full first (or ending in MemoryError or swapping).
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import numpy.typing as npt

from nlosfw.common import memory
from nlosfw.common.errors import DataError, one_line
from nlosfw.common.files import format_bytes
from nlosfw.common.reading import binary, hdf5_file

#: Soft links followed in a row before a chain is refused (a loop).
_MAX_SOFT_HOPS = 16


def dataset_limit() -> int:
    """Bytes a dataset of an input file may hold: the memory available now (within the
    physical memory of this machine); a larger one cannot be read."""
    try:
        physical = int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError):  # pragma: no cover - platforms without sysconf
        physical = 1 << 40
    room = memory.available_memory()
    return physical if room is None else min(physical, room)


@contextlib.contextmanager
def open_checked(path: Path, what: str = "file") -> Iterator[h5py.File]:
    """``path`` open read-only with h5py after :func:`check_file`; h5py's errors opening it
    become a one-line DataError ("not a readable HDF5 ``what``": truncated or corrupt, or
    not HDF5 at all)."""
    with contextlib.ExitStack() as stack:
        try:
            f = stack.enter_context(hdf5_file(path))
        except OSError as err:
            reason = "truncated or corrupt" if _has_signature(path) else "not HDF5"
            raise DataError(f"{path}: not a readable HDF5 {what} ({reason}: "
                            f"{one_line(err)})") from None
        check_file(f, path)
        yield f


def _has_signature(path: Path) -> bool:
    """Whether ``path`` starts with HDF5's signature (at 0 or after a user block)."""
    try:
        with binary(path) as f:
            head = f.read(2048 + 8)
    except OSError:
        return False
    return any(head[at:at + 8] == b"\x89HDF\r\n\x1a\n" for at in (0, 512, 1024, 2048))


def check_file(f: h5py.File, path: Path) -> None:
    """Refuse (DataError naming ``path`` and the object) an HDF5 file with an external
    link, a soft link that does not resolve inside the file, a virtual dataset or a
    dataset whose raw data lives in external files, anywhere in it."""
    seen: set[object] = set()
    stack: list[tuple[h5py.Group, str]] = [(f, "")]
    while stack:
        group, prefix = stack.pop()
        for name in list(group.keys()):
            where = f"{prefix}/{name}" if prefix else name
            try:
                link = group.get(name, getlink=True)
            except (KeyError, OSError, RuntimeError) as err:
                raise DataError(f"{path}: object '{where}' cannot be read (truncated or "
                                f"corrupt: {one_line(err)})") from None
            if isinstance(link, h5py.ExternalLink):
                raise DataError(f"{path}: '{where}' is an external link to "
                                f"{link.filename}:{link.path}; links to other files are "
                                "refused (copy the data into the capture file)")
            if isinstance(link, h5py.SoftLink):
                _check_soft_link(f, link.path, group.name, path, where)
                continue
            try:
                node = group[name]
            except (KeyError, OSError, RuntimeError) as err:
                raise DataError(f"{path}: object '{where}' cannot be read (truncated or "
                                f"corrupt: {one_line(err)})") from None
            if isinstance(node, h5py.Dataset):
                check_storage(node, path, where)
            elif isinstance(node, h5py.Group):
                key = (node.id.fileno, h5py.h5o.get_info(node.id).addr)
                if key not in seen:
                    seen.add(key)
                    stack.append((node, where))


def check_storage(node: h5py.Dataset, path: Path, where: str) -> None:
    """Refuse a virtual dataset or one with external raw storage."""
    if getattr(node, "is_virtual", False):
        raise DataError(f"{path}: dataset '{where}' is a virtual dataset (it maps data from "
                        "other files); refused: copy the data into the capture file")
    count = node.id.get_create_plist().get_external_count()
    if count:
        raise DataError(f"{path}: dataset '{where}' stores its data in {count} external "
                        "file(s) outside the capture; refused: copy the data into the "
                        "capture file")


def _check_soft_link(f: h5py.File, target: str, base: str, path: Path, where: str) -> None:
    """A soft link ``where`` to ``target`` must end at an object of this file, through
    hard links only (no external link on the way, no loop)."""
    for _ in range(_MAX_SOFT_HOPS):
        full = target if target.startswith("/") else f"{base.rstrip('/')}/{target}"
        parts = [p for p in full.split("/") if p and p != "."]
        node: h5py.Group = f
        current = "/"
        for i, part in enumerate(parts):
            if not isinstance(node, h5py.Group) or part not in node:
                raise DataError(f"{path}: '{where}' is a soft link to '{target}', which is "
                                "not an object of this file; refused")
            link = node.get(part, getlink=True)
            if isinstance(link, h5py.ExternalLink):
                raise DataError(f"{path}: '{where}' is a soft link through an external link "
                                f"to {link.filename}:{link.path}; links to other files are "
                                "refused")
            if isinstance(link, h5py.SoftLink):
                rest = "/".join(parts[i + 1:])
                target = link.path + (f"/{rest}" if rest else "")
                base = current
                break
            node = node[part]
            current = node.name
        else:
            return
    raise DataError(f"{path}: '{where}' is a chain of more than {_MAX_SOFT_HOPS} soft links "
                    "(a loop?); refused")


def declared_bytes(node: h5py.Dataset) -> int:
    """Bytes a dataset holds once read: its shape × its dtype's size (no data read)."""
    shape = node.shape or ()
    dtype = np.dtype(node.dtype)
    return math.prod(int(n) for n in shape) * max(dtype.itemsize, 1)


def check_size(node: h5py.Dataset, path: Path, where: str,
               dtype: npt.DTypeLike | None = None) -> None:
    """Refuse a dataset that declares more bytes (read as ``dtype`` if given) than
    :func:`dataset_limit`, before any of it is read."""
    shape = node.shape or ()
    itemsize = np.dtype(dtype if dtype is not None else node.dtype).itemsize
    nbytes = math.prod(int(n) for n in shape) * max(itemsize, 1)
    limit = dataset_limit()
    if nbytes > limit:
        raise DataError(f"{path}: dataset '{where}' declares {format_bytes(nbytes)} (shape "
                        f"{list(shape)} of {np.dtype(node.dtype)}), more than the "
                        f"{format_bytes(limit)} of memory available; refused before "
                        "reading it")


@dataclass(frozen=True)
class Expected:
    """The shapes a dataset (or a MATLAB variable) may declare, checked from its header
    before any of it is read: ``allows(shape)``, and ``what`` for the message."""

    what: str
    """What is expected, for the message ("one number", "64 points [N, 3]", ...)."""
    allows: Callable[[tuple[int, ...]], bool]

    def check(self, shape: tuple[int, ...] | None, path: Path, where: str,
              noun: str = "dataset") -> None:
        """Refuse (DataError naming ``path``, the ``noun`` and ``where``) a declared
        ``shape`` this does not allow."""
        declared = tuple(int(n) for n in (shape or ()))
        if not self.allows(declared):
            raise DataError(f"{path}: {noun} '{where}' declares shape {list(declared)}; "
                            f"expected {self.what}; refused before reading it")


#: A shape of any size (sized against the memory available only).
ANY_SHAPE = Expected("any shape", lambda shape: True)


def values(*counts: int, what: str = "") -> Expected:
    """One of ``counts`` numbers, in any arrangement (a scalar, (1,), (1, 3), (3, 1), ...)."""
    default = " or ".join(str(c) for c in counts) + (" number" if counts == (1,) else " numbers")
    return Expected(what or default, lambda shape: math.prod(shape) in counts)


def points(*counts: int, what: str) -> Expected:
    """One of ``counts`` points of 3 coordinates: an axis of 3 first or last (N x 3 or
    3 x N, a grid (X, Y, 3) or (3, Y, X)) and 3 x count numbers."""
    numbers = {3 * c for c in counts}
    return Expected(what, lambda shape: len(shape) >= 1 and 3 in (shape[0], shape[-1])
                    and math.prod(shape) in numbers)


def ranks(*allowed: int, what: str) -> Expected:
    """A shape of any size with one of the ``allowed`` numbers of axes."""
    return Expected(what, lambda shape: len(shape) in allowed)


def is_numeric(node: h5py.Dataset) -> bool:
    """Whether a dataset holds real or complex numbers (or booleans), not text or
    references."""
    return np.dtype(node.dtype).kind in "biufc"


def check_header(node: h5py.Dataset, path: Path, where: str, expected: Expected,
                 dtype: npt.DTypeLike | None = None) -> None:
    """Refuse, from its header alone, a dataset stored outside the file, larger (read as
    ``dtype`` if given) than :func:`dataset_limit`, or of a shape ``expected`` does not
    allow."""
    check_storage(node, path, where)
    check_size(node, path, where, dtype)
    expected.check(node.shape, path, where)


def read_dataset(node: h5py.Dataset, path: Path, where: str,
                 dtype: npt.DTypeLike | None = None, *, expected: Expected
                 ) -> np.ndarray | np.generic | bytes | str:
    """The value of dataset ``node`` (storage, ``expected`` shape and size checked first,
    from its header), converted to ``dtype`` while reading if given; a read error becomes a
    one-line DataError."""
    check_header(node, path, where, expected, dtype)
    try:
        if dtype is not None:
            return np.asarray(node.astype(dtype)[()])
        return node[()]
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: dataset '{where}' cannot be read (file truncated or corrupt: "
                        f"{one_line(err)})") from None

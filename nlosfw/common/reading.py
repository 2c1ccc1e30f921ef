"""One input file read through one descriptor: opened once while it is detected, sized from
its header, read and hashed.

A capture file's readers (the formats' detection, their headers, their full reads, the
HDF5 and MATLAB helpers, the file's digest) each open it by name. Within
:func:`read_once` they read through the descriptor it opened instead (:func:`binary`,
:func:`hdf5_file`, :func:`digest`): the file is opened once, whatever it is named by (a
link or another spelling of the same file), and what several readers would each compute
from it (a MATLAB file's list of variables) is computed once (:meth:`OpenedFile.memo`).
Outside the block, or for another file (a background, a ``tof.mat``), they open it as
usual.

The open file is this context's (a :class:`~contextvars.ContextVar`, set for the block):
another thread or a nested run reads its own files.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, TypeVar

if TYPE_CHECKING:
    import h5py

T = TypeVar("T")

#: Bytes read at a time to hash a file.
_BLOCK = 1 << 20


class OpenedFile:
    """A file open for reading for the length of a :func:`read_once` block."""

    def __init__(self, path: Path, handle: BinaryIO) -> None:
        self.path = path
        self.handle = handle
        status = os.fstat(handle.fileno())
        self.identity = (status.st_dev, status.st_ino)
        self._memo: dict[str, object] = {}
        self._digest: str | None = None

    def names(self, path: Path | str) -> bool:
        """Whether ``path`` names this file (a link, a relative or another spelling
        included)."""
        try:
            status = os.stat(path)
        except (OSError, ValueError):
            return False
        return (status.st_dev, status.st_ino) == self.identity

    def memo(self, key: str, compute: Callable[[], T]) -> T:
        """``compute()`` once per ``key`` for this file (what several readers ask of it)."""
        if key not in self._memo:
            self._memo[key] = compute()
        found: T = self._memo[key]  # type: ignore[assignment]
        return found

    def digest(self) -> str:
        """SHA-256 of the file's bytes, read through this descriptor (once)."""
        if self._digest is None:
            digest = hashlib.sha256()
            self.handle.seek(0)
            for block in iter(lambda: self.handle.read(_BLOCK), b""):
                digest.update(block)
            self._digest = digest.hexdigest()
        return self._digest


_CURRENT: ContextVar[OpenedFile | None] = ContextVar("nlosfw_opened_file", default=None)


def opened(path: Path | str) -> OpenedFile | None:
    """The file :func:`read_once` holds open, if ``path`` names it."""
    current = _CURRENT.get()
    return current if current is not None and current.names(path) else None


@contextmanager
def read_once(path: Path) -> Iterator[OpenedFile]:
    """Open ``path`` once for the block: every reader of it goes through this descriptor
    (within a block already open on the same file, that one). OSError as ``open``."""
    current = opened(path)
    if current is not None:
        yield current
        return
    with open(path, "rb") as handle:
        file = OpenedFile(Path(path), handle)
        token = _CURRENT.set(file)
        try:
            yield file
        finally:
            _CURRENT.reset(token)


@contextmanager
def binary(path: Path | str) -> Iterator[BinaryIO]:
    """``path`` open for reading in binary, at its start: the descriptor :func:`read_once`
    holds when it names that file (left open at the end), else a new one."""
    current = opened(path)
    if current is None:
        with open(path, "rb") as handle:
            yield handle
        return
    current.handle.seek(0)
    yield current.handle


@contextmanager
def hdf5_file(path: Path | str) -> Iterator[h5py.File]:
    """``path`` open read-only with h5py: through :func:`read_once`'s descriptor when it
    names that file, else by name. OSError as ``h5py.File``."""
    import h5py

    current = opened(path)
    if current is None:
        with h5py.File(path, "r") as f:
            yield f
        return
    current.handle.seek(0)
    with h5py.File(current.handle, "r") as f:
        yield f


def digest(path: Path) -> str:
    """SHA-256 of ``path``'s bytes (through :func:`read_once`'s descriptor, once, when it
    names that file)."""
    current = opened(path)
    if current is not None:
        return current.digest()
    hashed = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(_BLOCK), b""):
            hashed.update(block)
    return hashed.hexdigest()

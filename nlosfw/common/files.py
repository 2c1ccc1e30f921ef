"""Atomic, no-clobber file publication: write to a temporary name, then link or rename.

A write that fails because the disk is full or the directory is not writable raises a
one-line :class:`~nlosfw.common.errors.StorageError` naming the path (and the space
needed); the temporary file is removed, so nothing partial is ever left behind.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from nlosfw.common.errors import ConfigError, DataError, StorageError

#: errno values meaning "the disk (or the quota) is full".
_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
#: errno values meaning "this place cannot be written".
_UNWRITABLE = {errno.EROFS, errno.EACCES, errno.EPERM}
#: Headroom kept free beyond a write's known size (file-system metadata).
_HEADROOM = 64 << 10

#: Temporary names of :func:`atomic_path`: ``.<stem>.<pid>.<8 hex>.tmp<suffix>``.
TEMPORARY_NAME = re.compile(r"^\..+\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp(\.[^.]+)?$")


def is_regular_file(path: str | Path, follow: bool = True) -> bool:
    """Whether ``path`` is a regular file (a link followed unless not ``follow``), checked
    without opening it: a FIFO, a device or a directory in a file's place is never opened
    (opening a FIFO blocks until a writer comes)."""
    import stat

    try:
        info = os.stat(path) if follow else os.lstat(path)
    except (OSError, ValueError):
        return False
    return stat.S_ISREG(info.st_mode)


def unwritable_reason(folder: str | Path) -> str | None:
    """Why nothing can be created in the existing folder ``folder`` (``permission denied``,
    ``read-only file system``), or None when it can."""
    if os.access(folder, os.W_OK | os.X_OK):
        return None
    try:  # tell a read-only file system from missing permissions
        probe = os.open(folder, os.O_RDONLY)
        os.close(probe)
        reason = "permission denied"
        if hasattr(os, "statvfs") and os.statvfs(folder).f_flag & os.ST_RDONLY:
            reason = "read-only file system"
    except OSError as err:
        reason = os.strerror(err.errno or errno.EACCES)
    return reason


def format_bytes(n: float) -> str:
    """``n`` bytes in a short human form: ``512 B``, ``1.5 MB`` (decimal units, as ``ls -h
    --si`` and file browsers show them)."""
    units = ("B", "kB", "MB", "GB", "TB")
    for unit in units[:-1]:
        if abs(n) < 1000:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} {units[-1]}"


def free_space(path: str | Path) -> int:
    """Bytes free for an unprivileged writer on the file system holding ``path`` (or the
    nearest existing parent of it)."""
    target = Path(path).absolute()
    while not target.exists() and target != target.parent:
        target = target.parent
    return shutil.disk_usage(target).free


def ensure_free_space(path: str | Path, size: int) -> None:
    """Raise :class:`StorageError` unless ``size`` bytes (plus headroom) fit beside ``path``."""
    free = free_space(Path(path).parent)
    if free < size + _HEADROOM:
        raise StorageError(f"{path}: not enough disk space: writing it needs "
                           f"{format_bytes(size)}, {format_bytes(free)} free")


def storage_error(path: Path, err: OSError, written: int | None = None) -> StorageError | None:
    """The one-line :class:`StorageError` for an ``OSError`` of a write to ``path``, or None
    when ``err`` is not about full or unwritable storage."""
    if isinstance(err, StorageError):
        return err
    if err.errno in _FULL:
        needed = (f"it needs more than the {format_bytes(written)} written so far"
                  if written else "it needs more space")
        return StorageError(f"{path}: no space left on device ({needed}; "
                            f"{format_bytes(free_space(path.parent))} free)")
    if err.errno in _UNWRITABLE:
        reason = "read-only file system" if err.errno == errno.EROFS else "permission denied"
        return StorageError(f"{path.parent}: cannot write there ({reason})")
    return None


def output_error(err: OSError, option: str, path: Path | None = None
                 ) -> ConfigError | StorageError | None:
    """The one-line error of ``err`` writing to ``path`` (else ``err.filename``) in the
    output location ``option`` names: when it cannot be written (EROFS, EACCES, EPERM) a
    refusal (:class:`ConfigError`, exit status 2) naming the nearest existing folder on the
    way; a full disk's :func:`storage_error`; None for any other error."""
    where = Path(path if path is not None else err.filename or ".")
    if err.errno not in _UNWRITABLE:
        return storage_error(where, err)
    target = Path(os.path.abspath(where))
    while not target.exists() and target != target.parent:
        target = target.parent
    reason = "read-only file system" if err.errno == errno.EROFS else "permission denied"
    return ConfigError(option, f"{target} cannot be written ({reason}); choose another "
                               "output directory")


@contextlib.contextmanager
def atomic_path(path: str | Path, overwrite: bool = False,
                size: int | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; publish it as ``path`` if the block succeeds.

    Readers never see a half-written file, and on failure nothing is left behind.
    Unless ``overwrite`` is true an existing ``path`` is never replaced: the
    check and the publication are one atomic ``link``, so two writers racing
    for the same name cannot both win. ``size``, when known, is checked against
    the free space first. A full disk or an unwritable directory raises
    :class:`StorageError`.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise DataError(f"{path}: already exists; refusing to overwrite it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise (storage_error(path, err) or err) from None
    if size is not None:
        ensure_free_space(path, size)
    # keep the suffix last: some writers (numpy.savez) append their own otherwise
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        yield tmp
        if not tmp.exists():
            raise DataError(f"{path}: the writer produced no file")
        if overwrite:
            os.replace(tmp, path)
        else:
            _publish_no_clobber(tmp, path)
    except StorageError as err:  # from a nested atomic write: name the file being made
        if str(tmp) not in str(err):
            raise
        raise StorageError(str(err).replace(str(tmp), str(path))) from None
    except OSError as err:
        written = tmp.stat().st_size if tmp.exists() else None
        converted = storage_error(path, err, written)
        if converted is None:
            raise
        raise converted from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def _publish_no_clobber(tmp: Path, path: Path) -> None:
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise DataError(f"{path}: already exists; refusing to overwrite it") from None
    except OSError as err:  # file systems without hard links
        if err.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV):
            raise
        if path.exists():
            raise DataError(f"{path}: already exists; refusing to overwrite it") from None
        os.rename(tmp, path)


def write_text(path: str | Path, text: str, overwrite: bool = False) -> Path:
    """Atomically write a text file (UTF-8)."""
    return write_bytes(path, text.encode("utf-8"), overwrite=overwrite)


def write_bytes(path: str | Path, data: bytes | memoryview, overwrite: bool = False) -> Path:
    """Atomically write ``data`` (its size checked against the free space first)."""
    with atomic_path(path, overwrite=overwrite, size=len(data)) as tmp, open(tmp, "wb") as fh:
        view = memoryview(data)
        for start in range(0, len(view), 1 << 24):
            fh.write(view[start:start + (1 << 24)])
    return Path(path)


def open_locked(path: Path, blocking: bool, mode: str = "a") -> IO[str] | None:
    """``path`` (created if needed) opened in ``mode`` with an exclusive ``flock`` held, or
    None when not ``blocking`` and another process holds it. The lock is on the file the
    path names when it is taken: a lock file its holder removed meanwhile is not locked by
    mistake. Closing the handle drops the lock."""
    import fcntl

    flags = fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB)
    while True:
        handle = open(path, mode)  # noqa: SIM115 - returned open, closed by the caller
        try:
            fcntl.flock(handle, flags)
        except BlockingIOError:
            handle.close()
            return None
        try:
            if os.fstat(handle.fileno()).st_ino == os.stat(path).st_ino:
                return handle
        except FileNotFoundError:
            pass
        handle.close()

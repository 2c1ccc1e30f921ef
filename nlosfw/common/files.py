"""Atomic, no-clobber file publication: write to a temporary name, then link or rename."""

from __future__ import annotations

import contextlib
import errno
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

from nlosfw.common.errors import DataError


@contextlib.contextmanager
def atomic_path(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; publish it as ``path`` if the block succeeds.

    Readers never see a half-written file, and on failure nothing is left behind.
    Unless ``overwrite`` is true an existing ``path`` is never replaced: the
    check and the publication are one atomic ``link``, so two writers racing
    for the same name cannot both win.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise DataError(f"{path}: already exists; refusing to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
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
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)

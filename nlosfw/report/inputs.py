"""What a report reads: only regular files inside the folder it reports, each bounded.

The folder given to ``python -m nlosfw report DIR`` is untrusted: a file there may be a
link to a file elsewhere (whose contents a shareable report would carry), a FIFO (which
blocks the read) or a device, or be made to exhaust memory. A report therefore reads a
file only when it is a regular file inside DIR, its links followed (a link that stays
inside DIR is read), and only up to :data:`MAX_RUN_FILE_BYTES`; a run's own page reads
its figures the same way inside the run's folder.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

from nlosfw.common.errors import DataError
from nlosfw.common.files import is_regular_file

log = logging.getLogger(__name__)

#: The largest metrics.json, config.yaml or overrides.yaml a report reads (bytes): a run
#: writes a few kB to a few hundred kB.
MAX_RUN_FILE_BYTES = 16 << 20
#: The largest figure a run's page embeds (bytes).
MAX_FIGURE_BYTES = 256 << 20


def inside(path: str | Path, root: str | Path) -> bool:
    """Whether ``path`` is a regular file inside the folder ``root``, its links followed:
    neither a link that leaves ``root`` nor a FIFO, a device or a directory."""
    real = os.path.realpath(path)
    return Path(real).is_relative_to(os.path.realpath(root)) and is_regular_file(real)


def read_inside(path: str | Path, root: str | Path, limit: int = MAX_RUN_FILE_BYTES) -> bytes:
    """The bytes of ``path``, a regular file inside the folder ``root`` (links that stay
    inside it are followed) of at most ``limit`` bytes; a one-line :class:`DataError`
    naming it otherwise. A link leaving ``root``, a FIFO, a device, a directory and a
    larger file are never read (a FIFO never opened)."""
    real = os.path.realpath(path)
    if not Path(real).is_relative_to(os.path.realpath(root)):
        raise DataError(f"{path}: a link to {real}, outside {root}; it is not read (only the "
                        "files inside the folder are)")
    if not is_regular_file(real):
        raise DataError(f"{path}: not a regular file (a FIFO, a device or a directory); it "
                        "is not read")
    try:
        # no link followed now (one swapped in since is refused), and no wait on a FIFO
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
        with open(fd, "rb") as fh:
            info = os.fstat(fh.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise DataError(f"{path}: not a regular file; it is not read")
            data = fh.read(limit + 1) if info.st_size <= limit else b""
            size = max(info.st_size, len(data))
    except OSError as err:
        raise DataError(f"{path}: unreadable ({err.strerror or err})") from None
    if size > limit:
        raise DataError(f"{path}: {size:,} bytes, more than the {limit:,} a report reads from "
                        "one file; it is not read")
    return data


def figure_inside(path: Path, root: Path) -> bytes | None:
    """The bytes of the figure ``path`` when it is a regular file inside ``root`` (of at
    most :data:`MAX_FIGURE_BYTES`), else None (a warning in the log says why)."""
    if not os.path.lexists(path):
        return None
    try:
        return read_inside(path, root, MAX_FIGURE_BYTES)
    except DataError as err:
        log.warning("figure left out of the page: %s", err)
        return None

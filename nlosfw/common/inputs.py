"""Input files given by name: refused, in one line saying what the path really is, unless
it is a regular file (a directory, a FIFO, a device such as ``/dev/zero`` or a symlink
loop would otherwise hang a reader, or be reported as "file not found")."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from nlosfw.common.errors import ConfigError, DataError


def what_is(path: Path) -> str | None:
    """None for a regular file (or a symlink to one), else what ``path`` is, in words."""
    try:
        mode = os.stat(path).st_mode
    except OSError as err:
        if err.errno == errno.ELOOP:
            return "a symbolic link loop (it never reaches a file)"
        if err.errno == errno.ENAMETOOLONG:
            return "a name too long for the file system"
        if err.errno in (errno.EACCES, errno.EPERM):
            return "not accessible (permission denied)"
        if err.errno == errno.ENOTDIR:
            return "not found (a part of it is not a directory)"
        if os.path.islink(path):
            return "a dangling symbolic link (its target does not exist)"
        return "not found"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory, not a file"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, not a regular file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a regular file"
    return "not a regular file"


def describe_input(path: Path, what: str = "file") -> Path:
    """``path`` if it is a regular file; else a one-line DataError saying what it is."""
    problem = what_is(path)
    if problem is not None:
        raise DataError(f"{path}: {what} {_verb(problem)}")
    return path


def regular_file(value: str | Path, option: str) -> Path:
    """``value`` (``~`` expanded) as a path to a regular file; else a one-line ConfigError
    for ``option`` saying what it is."""
    path = Path(value).expanduser()
    problem = what_is(path)
    if problem == "not found":
        raise ConfigError(option, f"file not found: {value}")
    if problem is not None:
        raise ConfigError(option, f"{value} {_verb(problem)}")
    return path


def _verb(problem: str) -> str:
    return problem if problem.startswith("not ") else f"is {problem}"

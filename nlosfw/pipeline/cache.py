"""A content-addressed cache of captures and phasor fields.

An entry is keyed by the SHA-256 of the canonical JSON of everything that
produced it (plugin, its distribution and version, its options, the scene and
the contents of its mesh files, upstream keys), so a sweep over models
simulates each scene once. Each entry is stored with the SHA-256 of its bytes,
written before the entry appears; an entry whose bytes do not match, or that
cannot be read, is reported, removed and recomputed. A lock per key makes
concurrent runs (parallel or SLURM sweeps sharing the cache) wait for one
computation instead of repeating it.

The cache owns only what it wrote. Its directory holds a marker, ``.nlosfw-cache``, written
when the cache first stores there; a directory without the marker is never cleaned nor
evicted from (one whose files are all entries, ``<kind>/<64 hex>.hdf5`` with their
``.sha256``, is an older cache and is adopted: the marker is written then), and anywhere
else the run goes on without the cache. Only a regular file named ``<64 hex>.hdf5`` with a
regular ``<64 hex>.sha256`` beside it, in a sub-folder of the marked directory, is an
entry; anything else there (a user's file, a directory or a FIFO in an entry's place) is
never read, evicted or removed.

The cache never fails a run: an unwritable cache directory disables it (with a warning),
and an entry that cannot be stored (a full disk) is skipped, leaving nothing partial.
With ``max_gb`` the least recently used entries (by the time their checksum file was last
touched: when stored or read) are evicted beyond that size, never one whose lock a
running process holds. :func:`cache_info` and :func:`clean_cache` back
``python -m nlosfw cache info`` and ``cache clean``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import stat
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from nlosfw.common.errors import DataError
from nlosfw.common.files import TEMPORARY_NAME, atomic_path, open_locked, write_text
from nlosfw.common.hashing import file_digest

log = logging.getLogger(__name__)
T = TypeVar("T")

#: The cache directory when none is configured (``cache.dir``'s default in config.yaml).
DEFAULT_DIR = "~/.cache/nlosfw"


#: The marker file at the root of a cache directory: the cache's claim on it.
MARKER_NAME = ".nlosfw-cache"
MARKER_FORMAT = "nlosfw-cache"
#: An entry's file name: the key (the SHA-256 of what produced it) and ``.hdf5``.
ENTRY_NAME = re.compile(r"^(?P<key>[0-9a-f]{64})\.hdf5$")
#: The files an entry is made of besides ``<key>.hdf5``.
_ENTRY_SUFFIXES = (".sha256", ".lock")
_KIND_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


def default_cache_dir() -> Path:
    """``$NLOSFW_CACHE_DIR``, else ``~/.cache/nlosfw`` (as ``cache.dir`` defaults)."""
    return Path(os.environ.get("NLOSFW_CACHE_DIR") or DEFAULT_DIR).expanduser()


def _regular(path: Path) -> bool:
    """Whether ``path`` is a regular file (not followed through a link; never opened)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def owns(root: Path) -> bool:
    """Whether the cache owns ``root``: its marker is there (a regular file saying so)."""
    marker = root / MARKER_NAME
    if not _regular(marker):
        return False
    try:
        with open(marker, encoding="utf-8") as f:
            found = json.loads(f.read(4096) or "null")
    except (OSError, ValueError):
        return False
    return isinstance(found, dict) and found.get("format") == MARKER_FORMAT


def claim(root: Path, adopt_only: bool = False) -> bool:
    """Make ``root`` the cache's: True when it already is, or when it is new, empty (unless
    ``adopt_only``) or an older cache (every file in it an entry's), the marker then
    written. False when it holds anything else: the cache then never touches it."""
    if owns(root):
        return True
    if not _adoptable(root, allow_empty=not adopt_only):
        return False
    root.mkdir(parents=True, exist_ok=True)
    write_text(root / MARKER_NAME, json.dumps({"format": MARKER_FORMAT, "version": 1}) + "\n",
               overwrite=True)
    return True


def _adoptable(root: Path, allow_empty: bool) -> bool:
    """Whether ``root`` is absent or empty (when ``allow_empty``) or holds only entries
    (``<kind>/<64 hex>.hdf5`` each with its ``.sha256``, their locks and temporaries)."""
    if not root.exists():
        return allow_empty
    if not root.is_dir() or root.is_symlink():
        return False
    entries = 0
    for kind in root.iterdir():
        if kind.name.startswith(".probe-"):
            continue
        if not (kind.is_dir() and not kind.is_symlink() and _KIND_NAME.match(kind.name)):
            return False
        for path in kind.iterdir():
            if TEMPORARY_NAME.match(path.name) and _regular(path):
                continue
            stem, suffix = path.name[:64], path.name[64:]
            if not (ENTRY_NAME.match(stem + ".hdf5") and suffix in (".hdf5", *_ENTRY_SUFFIXES)
                    and _regular(path)):
                return False
            if suffix == ".hdf5":
                if not _regular(path.with_suffix(".sha256")):
                    return False
                entries += 1
    return allow_empty or entries > 0


@dataclass(frozen=True)
class CacheEntry:
    """One stored entry: its file, the size of it and its checksum, its last use."""

    path: Path
    nbytes: int
    last_used: float

    @property
    def check(self) -> Path:
        return self.path.with_suffix(".sha256")

    @property
    def lock(self) -> Path:
        return self.path.with_suffix(".lock")


def cache_entries(root: Path) -> list[CacheEntry]:
    """Every entry under ``root`` (a regular ``<kind>/<64 hex>.hdf5`` with a regular
    ``.sha256`` beside it), least recently used first; none when the cache does not own
    ``root`` (no marker)."""
    out: list[CacheEntry] = []
    if not root.is_dir() or not owns(root):
        return out
    for kind in sorted(p for p in root.iterdir() if p.is_dir() and not p.is_symlink()):
        for path in kind.iterdir():
            if not ENTRY_NAME.match(path.name):
                continue
            check = path.with_suffix(".sha256")
            try:
                data, checked = os.lstat(path), os.lstat(check)
            except OSError:  # no checksum (not an entry), or removed meanwhile
                continue
            if not (stat.S_ISREG(data.st_mode) and stat.S_ISREG(checked.st_mode)):
                continue  # not something the cache wrote: never touched
            out.append(CacheEntry(path=path, nbytes=data.st_size + checked.st_size,
                                  last_used=checked.st_mtime))
    return sorted(out, key=lambda e: (e.last_used, str(e.path)))


def evict(entry: CacheEntry) -> bool:
    """Remove ``entry`` unless a running process holds its lock; True when removed."""
    if entry.lock.exists() and not _regular(entry.lock):
        return False  # a lock that is not a file: not the cache's, left alone
    handle = open_locked(entry.lock, blocking=False)
    if handle is None:
        return False
    try:
        for path in (entry.path, entry.check, entry.lock):
            if _regular(path):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
    finally:
        handle.close()
    return True


class Cache:
    """Entries under ``root/<kind>/<key>.hdf5`` with ``<key>.sha256`` beside them."""

    def __init__(self, root: str | Path, enabled: bool = True,
                 max_gb: float | None = None) -> None:
        self.root = Path(root).expanduser()
        self.enabled = enabled
        self.max_bytes = (None if max_gb is None or not math.isfinite(max_gb)
                          else int(max(max_gb, 0.0) * 1e9))
        self._checked = False

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], T],
                       write: Callable[[Path, T], Path | None],
                       read: Callable[[Path], T]) -> tuple[T, bool]:
        """The cached value for ``key`` (a SHA-256, 64 hex digits) or ``compute()`` (then
        stored). Returns (value, hit)."""
        if not ENTRY_NAME.match(f"{key}.hdf5") or not _KIND_NAME.match(kind):
            raise ValueError(f"cache: {kind}/{key} is not <kind>/<64 hex digits>")
        if not self._usable():
            return compute(), False
        entry = self.root / kind / f"{key}.hdf5"
        lock = entry.with_suffix(".lock")
        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
            for path in (entry, entry.with_suffix(".sha256"), lock):
                if (path.exists() or path.is_symlink()) and not _regular(path):
                    raise OSError(f"{path} is not a regular file")
            handle = open_locked(lock, blocking=True)
            if handle is None:  # never, when blocking
                raise OSError(f"{lock} could not be locked")
        except OSError as err:  # an unusable cache must not fail the run
            log.warning("cache: %s is not usable (%s); computing without it", entry.parent,
                        err.strerror or err)
            return compute(), False
        with contextlib.closing(handle):  # closing drops the lock
            if _regular(entry):
                value = self._load(entry, read)
                if value is not None:
                    return value, True
            value = compute()
            stored = self._store(entry, value, write)
        if stored and self.max_bytes is not None:
            self._shrink(self.max_bytes, keep=entry)
        return value, False

    def _usable(self) -> bool:
        """Whether the cache is enabled and its directory writable (checked once; an
        unwritable one disables the cache with a warning)."""
        if not self.enabled or self._checked:
            return self.enabled
        self._checked = True
        try:
            if not claim(self.root):
                log.warning("cache: %s holds files nlosfw did not write (it has no %s "
                            "marker); running without the cache (choose another cache.dir)",
                            self.root, MARKER_NAME)
                self.enabled = False
                return False
            with tempfile.NamedTemporaryFile(dir=self.root, prefix=".probe-"):
                pass
        except OSError as err:
            log.warning("cache: %s is not writable (%s); running without the cache",
                        self.root, err.strerror or err)
            self.enabled = False
        return self.enabled

    @staticmethod
    def _store(entry: Path, value: T, write: Callable[[Path, T], Path | None]) -> bool:
        """Store ``value``; False (with a warning, nothing partial left) when it cannot be."""
        check = entry.with_suffix(".sha256")
        try:
            with atomic_path(entry) as tmp:
                write(tmp, value)
                write_text(check, file_digest(tmp) + "\n", overwrite=True)
        except (OSError, DataError) as err:  # a full or read-only cache must not fail the run
            log.warning("cache: could not store %s (%s)", entry, err)
            if not entry.exists():
                with contextlib.suppress(OSError):
                    check.unlink()
            return False
        return True

    def _load(self, entry: Path, read: Callable[[Path], T]) -> T | None:
        check = entry.with_suffix(".sha256")
        try:
            if not _regular(check):
                raise OSError("no checksum file")
            with open(check, encoding="ascii", errors="replace") as f:
                expected = f.read(100).strip()
            actual = file_digest(entry)
        except OSError as err:
            log.warning("cache: %s cannot be read (%s); recomputing", entry, err.strerror or err)
            self._evict(entry, check)
            return None
        if expected != actual:
            log.warning("cache: %s is corrupt (checksum mismatch); recomputing", entry)
            self._evict(entry, check)
            return None
        try:
            value = read(entry)
        except DataError as err:
            log.warning("cache: %s cannot be read (%s); recomputing", entry, err)
            self._evict(entry, check)
            return None
        with contextlib.suppress(OSError):
            os.utime(check)  # used now: the last to be evicted
        return value

    def _shrink(self, limit: int, keep: Path) -> None:
        """Evict least recently used entries (not ``keep``, none in use) beyond ``limit``."""
        entries = cache_entries(self.root)
        total = sum(e.nbytes for e in entries)
        for entry in entries:
            if total <= limit:
                return
            if entry.path != keep and evict(entry):
                total -= entry.nbytes
                log.info("cache: evicted %s (least recently used; cache.max_gb)", entry.path)

    @staticmethod
    def _evict(entry: Path, check: Path) -> None:
        for path in (entry, check):
            if _regular(path):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()


@dataclass(frozen=True)
class CacheInfo:
    """What ``cache info`` reports."""

    root: Path
    entries: int
    nbytes: int
    by_kind: dict[str, tuple[int, int]]
    """kind -> (entries, bytes)."""
    temporaries: int


def cache_info(root: Path) -> CacheInfo:
    """The entries and sizes under ``root``."""
    entries = cache_entries(root)
    by_kind: dict[str, tuple[int, int]] = {}
    for e in entries:
        n, size = by_kind.get(e.path.parent.name, (0, 0))
        by_kind[e.path.parent.name] = (n + 1, size + e.nbytes)
    return CacheInfo(root=root, entries=len(entries), nbytes=sum(e.nbytes for e in entries),
                     by_kind=by_kind, temporaries=len(_stale_temporaries(root)))


def clean_cache(root: Path, keep_bytes: int = 0) -> tuple[int, int, int]:
    """Evict least recently used entries until at most ``keep_bytes`` remain, and remove
    temporaries of processes that no longer run. Returns (entries removed, bytes freed,
    entries skipped because a running process holds them). A directory the cache does
    not own (no marker, not an older cache to adopt) is left untouched: nothing removed."""
    if not root.is_dir() or not claim(root, adopt_only=True):
        return 0, 0, 0
    entries = cache_entries(root)
    total = sum(e.nbytes for e in entries)
    removed = freed = busy = 0
    for entry in entries:
        if total <= keep_bytes:
            break
        if evict(entry):
            removed, freed, total = removed + 1, freed + entry.nbytes, total - entry.nbytes
        else:
            busy += 1
    for path in _stale_temporaries(root):
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    return removed, freed, busy


def _stale_temporaries(root: Path, min_age: float = 3600.0) -> list[Path]:
    """Temporary files (of :func:`~nlosfw.common.files.atomic_path`) older than ``min_age``
    seconds whose process no longer runs on this machine (the age guards a cache shared
    with other machines, whose process ids mean nothing here)."""
    if not root.is_dir() or not owns(root):
        return []
    out = []
    now = time.time()
    for path in root.glob("*/.*"):
        match = TEMPORARY_NAME.match(path.name)
        try:
            old = now - path.lstat().st_mtime >= min_age and _regular(path)
        except FileNotFoundError:
            continue
        if match and old and not _alive(int(match.group("pid"))):
            out.append(path)
    return out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True

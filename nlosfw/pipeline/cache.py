"""A content-addressed cache of captures and phasor fields.

An entry is keyed by the SHA-256 of the canonical JSON of everything that
produced it (plugin, its distribution and version, its options, the scene and
the contents of its mesh files, upstream keys), so a sweep over models
simulates each scene once. Each entry is stored with the SHA-256 of its bytes,
written before the entry appears; an entry whose bytes do not match, or that
cannot be read, is reported, removed and recomputed. A lock per key makes
concurrent runs (parallel or SLURM sweeps sharing the cache) wait for one
computation instead of repeating it.

The cache never fails a run: an unwritable cache directory disables it (with a warning),
and an entry that cannot be stored (a full disk) is skipped, leaving nothing partial.
With ``max_gb`` the least recently used entries (by the time their checksum file was last
touched: when stored or read) are evicted beyond that size, never one whose lock a
running process holds. :func:`cache_info` and :func:`clean_cache` back
``python -m nlosfw cache info`` and ``cache clean``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
import time
from collections.abc import Callable, Iterator
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


def default_cache_dir() -> Path:
    """``$NLOSFW_CACHE_DIR``, else ``~/.cache/nlosfw`` (as ``cache.dir`` defaults)."""
    return Path(os.environ.get("NLOSFW_CACHE_DIR") or DEFAULT_DIR).expanduser()


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (created if needed) for the block."""
    handle = open_locked(path, blocking=True)
    assert handle is not None  # a blocking lock is always taken
    try:
        yield
    finally:
        handle.close()


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
    """Every entry under ``root`` (``<kind>/<key>.hdf5``), least recently used first."""
    out: list[CacheEntry] = []
    if not root.is_dir():
        return out
    for kind in sorted(p for p in root.iterdir() if p.is_dir()):
        for path in kind.glob("*.hdf5"):
            if path.name.startswith("."):
                continue  # a temporary
            check = path.with_suffix(".sha256")
            try:
                size = path.stat().st_size
                used = check.stat().st_mtime if check.exists() else 0.0
                size += check.stat().st_size if check.exists() else 0
            except FileNotFoundError:  # removed meanwhile
                continue
            out.append(CacheEntry(path=path, nbytes=size, last_used=used))
    return sorted(out, key=lambda e: (e.last_used, str(e.path)))


def evict(entry: CacheEntry) -> bool:
    """Remove ``entry`` unless a running process holds its lock; True when removed."""
    handle = open_locked(entry.lock, blocking=False)
    if handle is None:
        return False
    try:
        for path in (entry.path, entry.check, entry.lock):
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
        self.max_bytes = None if max_gb is None else int(max_gb * 1e9)
        self._checked = False

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], T],
                       write: Callable[[Path, T], Path | None],
                       read: Callable[[Path], T]) -> tuple[T, bool]:
        """The cached value for ``key`` or ``compute()`` (then stored). Returns (value, hit)."""
        if not self._usable():
            return compute(), False
        entry = self.root / kind / f"{key}.hdf5"
        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:  # an unusable cache must not fail the run
            log.warning("cache: %s is not usable (%s); computing without it", entry.parent, err)
            return compute(), False
        with _locked(entry.with_suffix(".lock")):
            if entry.exists():
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
            self.root.mkdir(parents=True, exist_ok=True)
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
        expected = check.read_text().strip() if check.exists() else ""
        if expected != file_digest(entry):
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
    entries skipped because a running process holds them)."""
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
    if not root.is_dir():
        return []
    out = []
    now = time.time()
    for path in root.glob("*/.*"):
        match = TEMPORARY_NAME.match(path.name)
        try:
            old = now - path.stat().st_mtime >= min_age
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

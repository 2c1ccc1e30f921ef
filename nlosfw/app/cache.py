"""A content-addressed cache of captures and phasor fields.

An entry is keyed by the SHA-256 of the canonical JSON of everything that
produced it (plugin, its distribution and version, its options, the scene and
the contents of its mesh files, upstream keys), so a sweep over models
simulates each scene once. Each entry is stored with the SHA-256 of its bytes,
written before the entry appears; an entry whose bytes do not match, or that
cannot be read, is reported, removed and recomputed. A lock per key makes
concurrent runs (parallel or SLURM sweeps sharing the cache) wait for one
computation instead of repeating it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from nlosfw.common.errors import DataError
from nlosfw.common.files import atomic_path, write_text
from nlosfw.common.version import __version__

log = logging.getLogger(__name__)
T = TypeVar("T")


def cache_key(material: Any) -> str:
    """SHA-256 of the canonical JSON of ``material`` plus the nlosfw version."""
    text = json.dumps({"nlosfw": __version__, "material": material}, sort_keys=True,
                      separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (created if needed) for the block."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no cross-process lock
        yield
        return
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


class Cache:
    """Entries under ``root/<kind>/<key>.hdf5`` with ``<key>.sha256`` beside them."""

    def __init__(self, root: str | Path, enabled: bool = True) -> None:
        self.root = Path(root).expanduser()
        self.enabled = enabled

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], T],
                       write: Callable[[Path, T], Any],
                       read: Callable[[Path], T]) -> tuple[T, bool]:
        """The cached value for ``key`` or ``compute()`` (then stored). Returns (value, hit)."""
        if not self.enabled:
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
            self._store(entry, value, write)
        return value, False

    @staticmethod
    def _store(entry: Path, value: Any, write: Callable[[Path, Any], Any]) -> None:
        check = entry.with_suffix(".sha256")
        try:
            with atomic_path(entry) as tmp:
                write(tmp, value)
                write_text(check, file_digest(tmp) + "\n", overwrite=True)
        except (OSError, DataError) as err:  # a full or read-only cache must not fail the run
            log.warning("cache: could not store %s (%s)", entry, err)

    def _load(self, entry: Path, read: Callable[[Path], T]) -> T | None:
        check = entry.with_suffix(".sha256")
        expected = check.read_text().strip() if check.exists() else ""
        if expected != file_digest(entry):
            log.warning("cache: %s is corrupt (checksum mismatch); recomputing", entry)
            self._evict(entry, check)
            return None
        try:
            return read(entry)
        except DataError as err:
            log.warning("cache: %s cannot be read (%s); recomputing", entry, err)
            self._evict(entry, check)
            return None

    @staticmethod
    def _evict(entry: Path, check: Path) -> None:
        for path in (entry, check):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()

"""A content-addressed cache of captures and phasor fields.

An entry is keyed by the SHA-256 of the canonical JSON of everything that
produced it (plugin name and options, scene, upstream keys, nlosfw version),
so a sweep over models simulates each scene once. Each entry is stored with
the SHA-256 of its bytes; an entry whose bytes no longer match, or that cannot
be read, is reported, removed and recomputed.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from nlosfw import __version__
from nlosfw.errors import DataError
from nlosfw.io.atomic import atomic_path, write_text

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
        check = entry.with_suffix(".sha256")
        if entry.exists():
            value = self._load(entry, check, read)
            if value is not None:
                return value, True
        value = compute()
        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(entry) as tmp:
                write(tmp, value)
            write_text(check, file_digest(entry) + "\n", overwrite=True)
        except (OSError, DataError) as err:  # a full or read-only cache must not fail the run
            log.warning("cache: could not store %s (%s)", entry, err)
        return value, False

    def _load(self, entry: Path, check: Path, read: Callable[[Path], T]) -> T | None:
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

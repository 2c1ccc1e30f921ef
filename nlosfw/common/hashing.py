"""Content hashes: of JSON-like values (cache keys, configuration hashes) and of files."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from nlosfw.common.reading import digest
from nlosfw.common.version import __version__


def canonical_digest(value: object) -> str:
    """SHA-256 of the canonical JSON of ``value`` (sorted keys, no spaces, ``str`` for what
    JSON cannot hold): equal values give equal digests whatever their key order."""
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def cache_key(material: object) -> str:
    """The cache key of what ``material`` describes: its canonical digest with the nlosfw
    version, so that an upgrade never reads an entry an older version wrote."""
    return canonical_digest({"nlosfw": __version__, "material": material})


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes (read in 1 MiB blocks; through the open descriptor, and
    once, while :func:`nlosfw.common.reading.read_once` holds that file)."""
    return digest(path)

"""``python -m nlosfw cache info`` and ``python -m nlosfw cache clean``.

``info`` lists the cache's entries by kind and their size; ``clean`` evicts the least
recently used entries (all of them, or down to ``--keep-gb``), never one a running process
is using, and removes temporary files left by processes that died. The cache directory
is ``--dir``, else ``$NLOSFW_CACHE_DIR``, else ``~/.cache/nlosfw`` (``cache.dir``'s
default). Only a directory the cache owns (its ``.nlosfw-cache`` marker, or an older cache
whose files are all entries) is cleaned: ``clean`` pointed anywhere else removes nothing
and says so. Mistakes end with one line and exit status 2; a directory that cannot be
written, with one line and exit status 1.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from rich.console import Console

from nlosfw.common.errors import ConfigError
from nlosfw.common.files import format_bytes, storage_error
from nlosfw.pipeline.cache import (
    MARKER_NAME,
    cache_info,
    claim,
    clean_cache,
    default_cache_dir,
    owns,
)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise ConfigError("", f"python -m nlosfw cache: {message}")


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m nlosfw cache", allow_abbrev=False,
                     description="Inspect or clean nlosfw's cache of captures and fields.")
    sub = parser.add_subparsers(dest="action", required=True, metavar="{info,clean}",
                                parser_class=_Parser)
    info = sub.add_parser("info", help="entries and sizes")
    clean = sub.add_parser("clean", help="evict least recently used entries")
    for p in (info, clean):
        p.add_argument("--dir", type=Path, default=None,
                       help="the cache directory (default: $NLOSFW_CACHE_DIR or "
                            "~/.cache/nlosfw)")
    clean.add_argument("--keep-gb", type=float, default=0.0,
                       help="keep the most recently used entries up to this size (GB)")
    return parser


def cache_command(argv: Sequence[str], console: Console | None = None) -> int:
    """Run ``cache info`` or ``cache clean``; returns the exit status."""
    args = _parser().parse_args(list(argv))
    console = console or Console(soft_wrap=True, highlight=False)
    root = (args.dir or default_cache_dir()).expanduser()
    if root.exists() and not root.is_dir():
        raise ConfigError("--dir", f"{root} is not a directory")
    if args.action == "info":
        if root.is_dir() and not owns(root) and not claim(root, adopt_only=True):
            console.print(f"{_shown(root)} is not an nlosfw cache (no {MARKER_NAME} marker); "
                          "it holds no entries")
            return 0
        info = cache_info(root)
        console.print(f"cache {root}: {info.entries} entries, {format_bytes(info.nbytes)}")
        for kind, (n, size) in sorted(info.by_kind.items()):
            console.print(f"  {kind}: {n} entries, {format_bytes(size)}")
        if info.temporaries:
            console.print(f"  {info.temporaries} temporary files of processes that died "
                          "(cache clean removes them)")
        return 0
    if not args.keep_gb >= 0:  # NaN too
        raise ConfigError("--keep-gb", f"must be >= 0, got {args.keep_gb}")
    if root.is_dir() and not claim(root, adopt_only=True):
        raise ConfigError("--dir", f"{_shown(root)} is not an nlosfw cache (no {MARKER_NAME} "
                          "marker, and it holds files nlosfw did not write); nothing was removed")
    keep = 1 << 62 if math.isinf(args.keep_gb) else int(args.keep_gb * 1e9)
    try:
        removed, freed, busy = clean_cache(root, keep)
    except OSError as err:
        raise (storage_error(root / "entry", err) or err) from None
    kept = f"; {busy} in use by running processes were kept" if busy else ""
    console.print(f"cache {root}: removed {removed} entries ({format_bytes(freed)}){kept}")
    return 0


def _shown(path: Path) -> str:
    """``path`` for a one-line message (control characters escaped)."""
    return ascii(str(path))[1:-1] if not str(path).isprintable() else str(path)

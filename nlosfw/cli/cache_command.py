"""``python -m nlosfw cache info`` and ``python -m nlosfw cache clean``.

``info`` lists the cache's entries by kind and their size; ``clean`` evicts the least
recently used entries (all of them, or down to ``--keep-gb``), never one a running process
is using, and removes temporary files left by processes that died. The cache directory
is ``--dir``, else ``$NLOSFW_CACHE_DIR``, else ``~/.cache/nlosfw`` (``cache.dir``'s
default). Mistakes end with one line and exit status 2; a directory that cannot be
written, with one line and exit status 1.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from rich.console import Console

from nlosfw.common.errors import ConfigError
from nlosfw.common.files import format_bytes, storage_error
from nlosfw.pipeline.cache import cache_info, clean_cache, default_cache_dir


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
        info = cache_info(root)
        console.print(f"cache {root}: {info.entries} entries, {format_bytes(info.nbytes)}")
        for kind, (n, size) in sorted(info.by_kind.items()):
            console.print(f"  {kind}: {n} entries, {format_bytes(size)}")
        if info.temporaries:
            console.print(f"  {info.temporaries} temporary files of processes that died "
                          "(cache clean removes them)")
        return 0
    if args.keep_gb < 0:
        raise ConfigError("--keep-gb", f"must be >= 0, got {args.keep_gb}")
    try:
        removed, freed, busy = clean_cache(root, int(args.keep_gb * 1e9))
    except OSError as err:
        raise (storage_error(root / "entry", err) or err) from None
    kept = f"; {busy} in use by running processes were kept" if busy else ""
    console.print(f"cache {root}: removed {removed} entries ({format_bytes(freed)}){kept}")
    return 0

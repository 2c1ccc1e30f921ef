"""The cache's size limit (least recently used entries evicted, never one in use) and the
``cache info`` / ``cache clean`` subcommands."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from nlosfw.pipeline.cache import Cache, cache_entries

ENTRY = 1000          # bytes of each test entry (its .sha256 adds 65)


def full(key: str) -> str:
    """The 64-hex-digit cache key of the short test key (``aaaa``: ``a`` 64 times)."""
    return key * (64 // len(key))


def put(cache: Cache, key: str) -> bool:
    """Store (or read back) entry ``key``; whether it was a hit."""
    _, hit = cache.get_or_compute("blobs", full(key), lambda: key.encode() * (ENTRY // len(key)),
                                  lambda p, v: p.write_bytes(v), lambda p: p.read_bytes())
    return hit


def age(root: Path, key: str, seconds_ago: float) -> None:
    """Mark entry ``key`` as last used ``seconds_ago``."""
    check = root / "blobs" / f"{full(key)}.sha256"
    t = check.stat().st_mtime - seconds_ago
    os.utime(check, (t, t))


def keys(root: Path) -> list[str]:
    return sorted(e.path.stem[:4] for e in cache_entries(root))


def test_the_least_recently_used_entries_go_beyond_max_gb(tmp_path):
    cache = Cache(tmp_path, max_gb=3.3e-6)        # room for three entries
    for n, key in enumerate(["aaaa", "bbbb", "cccc"]):
        put(cache, key)
        age(tmp_path, key, 100 - 10 * n)             # aaaa oldest, then bbbb, then cccc
    assert put(cache, "aaaa")                        # a hit: aaaa is now the most recent
    put(cache, "dddd")                               # one too many: the LRU one goes
    assert keys(tmp_path) == ["aaaa", "cccc", "dddd"]
    assert sum(e.nbytes for e in cache_entries(tmp_path)) <= 3.3e-6 * 1e9


def test_an_entry_in_use_by_another_process_is_never_evicted(tmp_path):
    cache = Cache(tmp_path, max_gb=2.2e-6)        # room for two entries
    put(cache, "aaaa")
    put(cache, "bbbb")
    age(tmp_path, "aaaa", 100)
    age(tmp_path, "bbbb", 50)
    lock = tmp_path / "blobs" / f"{full('aaaa')}.lock"
    holder = subprocess.Popen(     # holds the lock until its stdin closes, however long
        [sys.executable, "-c", "import fcntl, sys; f = open(sys.argv[1], 'a'); "
         "fcntl.flock(f, fcntl.LOCK_EX); print('held', flush=True); sys.stdin.read()",
         str(lock)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held", "the lock holder did not start"
        put(cache, "cccc")                           # aaaa is oldest but busy: bbbb goes
        assert keys(tmp_path) == ["aaaa", "cccc"]
    finally:
        holder.kill()
        holder.communicate(timeout=600)


def test_cache_info_and_clean(workdir, tools):
    root = workdir / "cache"
    cache = Cache(root)
    for n, key in enumerate(["aaaa", "bbbb", "cccc"]):
        put(cache, key)
        age(root, key, 100 - 10 * n)
    info = tools.run("cache", "info", "--dir", str(root))
    assert info.returncode == 0
    assert info.stdout.splitlines() == [f"cache {root}: 3 entries, 3.2 kB",
                                        "  blobs: 3 entries, 3.2 kB"]
    kept = tools.run("cache", "clean", "--dir", str(root), "--keep-gb", "2.2e-6")
    assert kept.returncode == 0
    assert kept.stdout.strip() == f"cache {root}: removed 1 entries (1.1 kB)"
    assert keys(root) == ["bbbb", "cccc"]
    everything = tools.run("cache", "clean")         # $NLOSFW_CACHE_DIR, set by workdir
    assert everything.returncode == 0 and keys(root) == []
    assert tools.run("cache", "info").stdout.strip() == f"cache {root}: 0 entries, 0 B"


@pytest.mark.parametrize(("args", "message"), [
    ([], "error: python -m nlosfw cache: the following arguments are required: {info,clean}"),
    (["frobnicate"], "error: python -m nlosfw cache: argument {info,clean}: invalid choice: "
                     "'frobnicate'"),
    (["clean", "--keep-gb", "-1"], "error: --keep-gb: must be >= 0, got -1.0"),
    (["info", "--dir", "__FILE__"], "error: --dir: __FILE__ is not a directory"),
])
def test_cache_command_mistakes(workdir, tools, args, message):
    a_file = workdir / "a-file"
    a_file.write_text("x")
    args = [str(a_file) if a == "__FILE__" else a for a in args]
    result = tools.run("cache", *args)
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith(message.replace("__FILE__", str(a_file)))


def test_cache_clean_on_a_read_only_cache(workdir, tools, read_only_cache):
    result = tools.run("cache", "clean", "--dir", str(read_only_cache))
    assert result.returncode == 1
    assert tools.one_error_line(result).startswith(
        f"error: {read_only_cache}: cannot write there (")
    assert len(cache_entries(read_only_cache)) == 1


def test_max_gb_is_checked_with_the_configuration(workdir, tools):
    result = tools.run("scene=tiny", "model=interp", "cache.max_gb=-1")
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        "error: cache.max_gb: must be >= 0 (GB) or null, got -1.0")

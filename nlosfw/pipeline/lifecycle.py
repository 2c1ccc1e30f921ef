"""A run's hold on its directory: a lock while it runs, a marker naming the files it wrote.

A run directory may hold other things than the run: a user's own files (with
``hydra.run.dir=.``), an earlier run, or a run still in progress. Two files make that
safe:

``.nlosfw-run.lock``  held (``flock``) by the running process, with its process id: a
                      second run in the same directory sees a live run and never touches
                      its files; the kernel drops the lock when the process dies, even by
                      ``kill -9``.
``.nlosfw-run.json``  the marker: the run's configuration hash and every file it has
                      claimed, recorded *before* the file is written. Only files listed
                      there are ever moved or removed by a later run.

A run directory inside the cache directory (``cache.dir``) is refused, and so is
``output.overwrite=true`` when a file the new run reads (``capture.path``,
``capture.background``, ``capture.tofgrid``) is one of the files it would replace.

What a later run does with an earlier one (:func:`verdict`): nothing to see: start;
a live run, or a file in the way that no run claimed: refuse (one line, exit status
2, nothing changed); an earlier run and ``output.overwrite=true``: remove its files,
then start; in a multirun (a sweep resumed in its directory) a finished job whose
configuration hash matches is skipped, an unfinished one is set aside under
``interrupted-<time>/`` and run again, and a different configuration is refused naming
the first option that differs; otherwise: refuse.
"""

from __future__ import annotations

import contextlib
import enum
import json
import logging
import os
import shutil
import socket
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, TypedDict

from nlosfw.common import yaml_safe
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.files import TEMPORARY_NAME, open_locked, output_error, write_text
from nlosfw.common.hashing import canonical_digest

if TYPE_CHECKING:
    from nlosfw.pipeline.settings import RunSettings

log = logging.getLogger(__name__)

LOCK_NAME = ".nlosfw-run.lock"
MARKER_NAME = ".nlosfw-run.json"
MARKER_FORMAT = "nlosfw-run"
#: Options that change where or whether a run computes, not what: left out of the hash.
RUN_CONTROL_OPTIONS = ("cache", "limits", "output.overwrite")
#: Hydra's own files in a run directory (never claimed, never touched).
HYDRA_FILES = (".hydra", "run.log")
#: Statuses of a finished run (one a resumed sweep may skip).
FINISHED = ("completed", "stopped")


class Verdict(enum.Enum):
    """What a run does with its directory."""

    start = "start"            # nothing of an earlier run there
    skip = "skip"              # a finished job of a resumed sweep, same configuration
    set_aside = "set_aside"    # an unfinished job of a resumed sweep: move its files aside
    replace = "replace"        # output.overwrite=true: remove the earlier run's files


class RunMarker(TypedDict):
    """The marker file's content: which run (process, host, configuration hash) claimed
    which files of the directory."""

    format: str
    version: int
    pid: int | str
    host: str
    config_hash: str
    files: list[str]


# --------------------------------------------------------------------- configuration
def _result_options(config: Mapping[str, object]) -> dict[str, object]:
    """``config`` (plain) without :data:`RUN_CONTROL_OPTIONS`."""
    plain = yaml_safe.to_plain(dict(config))
    for dotted in RUN_CONTROL_OPTIONS:
        *parents, leaf = dotted.split(".")
        node = plain
        for key in parents:
            node = node.get(key) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(leaf, None)
    return plain


def config_hash(config: Mapping[str, object]) -> str:
    """SHA-256 of the canonical JSON of a run's configuration, run-control options left out."""
    return canonical_digest(_result_options(config))


def first_difference(old: Mapping[str, object], new: Mapping[str, object]
                     ) -> tuple[str, object, object] | None:
    """(dotted option, old value, new value) of the first option that differs, or None."""
    a, b = _flatten(_result_options(old)), _flatten(_result_options(new))
    missing = object()
    for key in list(b) + [k for k in a if k not in b]:
        if a.get(key, missing) != b.get(key, missing):
            return key, a.get(key), b.get(key)
    return None


def _flatten(value: object, prefix: str = "") -> dict[str, object]:
    if isinstance(value, dict) and value:
        out: dict[str, object] = {}
        for key, item in value.items():
            out.update(_flatten(item, f"{prefix}.{key}" if prefix else str(key)))
        return out
    if isinstance(value, list) and value and any(isinstance(v, (dict, list)) for v in value):
        out = {}
        for i, item in enumerate(value):
            out.update(_flatten(item, f"{prefix}.{i}" if prefix else str(i)))
        return out
    return {prefix: value}


# ------------------------------------------------------------------------- inspection
@dataclass(frozen=True)
class EarlierRun:
    """What a run directory already holds."""

    live_pid: str | None = None
    """``pid@host`` of a run holding the directory's lock right now."""
    marker: RunMarker | None = None
    """The earlier run's marker (None: no nlosfw run claimed anything here)."""
    status: str | None = None
    """The earlier run's ``metrics.json`` status (None: it wrote none)."""
    in_the_way: tuple[str, ...] = ()
    """Names a run writes that exist here but that no run claimed."""

    @property
    def files(self) -> tuple[str, ...]:
        """The files the earlier run claimed (relative paths)."""
        return () if self.marker is None else tuple(self.marker["files"])


def inspect_run_dir(run_dir: Path, planned: Iterable[str], check_live: bool = True
                    ) -> EarlierRun:
    """What ``run_dir`` holds: a live run (unless not ``check_live``: the caller holds the
    lock), an earlier run's marker and status, and which of the ``planned`` top-level names
    are there without a run having claimed them."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return EarlierRun()
    live = _lock_holder(run_dir / LOCK_NAME) if check_live else None
    marker = _read_marker(run_dir / MARKER_NAME)
    claimed = {f.split("/", 1)[0] for f in ([] if marker is None else marker["files"])}
    if marker is not None:  # Hydra's files beside an earlier run are that run's
        claimed.update(HYDRA_FILES)
    in_the_way = tuple(name for name in planned
                       if name not in claimed and (run_dir / name).exists())
    status = None
    if marker is not None and "metrics.json" in claimed:
        try:
            status = json.loads((run_dir / "metrics.json").read_text()).get("status")
        except (OSError, ValueError, AttributeError):
            status = None
    return EarlierRun(live_pid=live, marker=marker, status=status, in_the_way=in_the_way)


def verdict(run_dir: Path, earlier: EarlierRun, config: Mapping[str, object],
            settings: RunSettings, *, resume: bool) -> Verdict:
    """What a run of ``config`` (its typed ``settings``) does with ``run_dir`` holding
    ``earlier``; a refusal is a one-line :class:`ConfigError` (exit status 2) and leaves the
    directory as it was. ``config`` is compared with an earlier run's, never read.

    ``resume``: the run is a job of a multirun (a sweep may be resumed in its directory).
    """
    overwrite = settings.output.overwrite
    check_outside_cache(run_dir, settings.cache.dir)
    if earlier.live_pid is not None:
        raise ConfigError("", f"{run_dir}: another nlosfw run (process {earlier.live_pid}) is "
                              "writing there; wait for it to end or choose another directory")
    if earlier.in_the_way:
        raise ConfigError("", f"{run_dir}: holds {earlier.in_the_way[0]}, which no nlosfw run "
                              "wrote there; choose another directory (nothing was changed)")
    if earlier.marker is None:
        return Verdict.start
    if overwrite:
        _check_inputs_kept(run_dir, earlier, settings.input_files)
        return Verdict.replace
    state = earlier.status if earlier.status in FINISHED else "unfinished"
    if not resume:
        article = "an" if state == "unfinished" else "a"
        raise ConfigError("output.overwrite", f"{run_dir} already holds {article} {state} run; "
                          "choose another directory, or set output.overwrite=true to replace "
                          "its files")
    if earlier.marker["config_hash"] != config_hash(config):
        raise _differs(run_dir, config)
    return Verdict.skip if state in FINISHED else Verdict.set_aside


def check_outside_cache(run_dir: Path, cache: str, option: str = "hydra.run.dir") -> None:
    """Refuse (one-line :class:`ConfigError`) a run directory inside ``cache.dir``, the
    directory ``cache`` (or the cache directory itself): the cache's directory holds only the
    cache's entries."""
    if not cache:
        return
    try:
        root = Path(cache).expanduser().resolve()
        where = Path(run_dir).expanduser().resolve()
    except (OSError, RuntimeError):  # a link loop: the directory checks say so
        return
    if where == root or root in where.parents:
        raise ConfigError(option, f"{run_dir} is inside the cache directory {root} "
                          "(cache.dir); choose a run directory outside it, or another "
                          "cache.dir")


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        info = path.stat()
    except (OSError, RuntimeError, ValueError):
        return None
    return info.st_dev, info.st_ino


def _check_inputs_kept(run_dir: Path, earlier: EarlierRun, inputs: Mapping[str, str]) -> None:
    """Refuse ``output.overwrite=true`` when a file the run reads (``inputs``, by option) is
    one it would replace."""
    replaced = {_identity(run_dir / name) for name in earlier.files} - {None}
    for option, value in inputs.items():
        if _identity(Path(value).expanduser()) in replaced:
            raise ConfigError(option, f"{value} is a file of the earlier run in {run_dir}, "
                              "which output.overwrite=true would remove; copy it elsewhere "
                              "and read the copy, or choose another run directory (nothing "
                              "was changed)")


def _differs(run_dir: Path, config: Mapping[str, object]) -> ConfigError:
    """The refusal of a resumed sweep job whose configuration is not the earlier one's."""
    hint = ("this sweep directory was run with another configuration; use a new "
            "hydra.sweep.dir, or output.overwrite=true to replace its runs")
    try:
        old = yaml_safe.load((run_dir / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, ValueError, yaml_safe.LimitExceeded):
        old = None
    found = first_difference(old, config) if isinstance(old, dict) else None
    if found is None:
        return ConfigError("", f"{run_dir}: {hint}")
    key, before, now = found
    new = key not in _flatten(_result_options(old))     # an option added or renamed since
    return ConfigError(key, (f"is an option the run in {run_dir} did not have (options "
                             "renamed since: nlosfw's changelog)" if new else
                             f"is {now!r} but {before!r} in the run in {run_dir}") + f"; {hint}")


# --------------------------------------------------------------------------- holding
class RunHold:
    """The running process's hold on its run directory: the lock and the marker.

    Create it with :meth:`acquire`; :meth:`claim` a file before writing it; :meth:`release`
    when the run ends (the marker stays, the lock goes).
    """

    def __init__(self, run_dir: Path, lock: IO[str], marker: RunMarker) -> None:
        self.run_dir = run_dir
        self._lock = lock
        self._marker = marker

    @classmethod
    def acquire(cls, run_dir: Path, config: Mapping[str, object], settings: RunSettings,
                planned: Iterable[str], *, resume: bool) -> RunHold | None:
        """Lock ``run_dir``, judge what it holds and act on it: None when the run is to be
        skipped (a finished job of a resumed sweep), else the hold. Raises the refusals of
        :func:`verdict` (the directory unchanged)."""
        run_dir = Path(run_dir)
        lock_path = run_dir / LOCK_NAME
        try:
            run_dir.mkdir(parents=True, exist_ok=True)
            existed = lock_path.exists()
            lock = open_locked(lock_path, blocking=False, mode="a+")
        except OSError as err:
            option = "hydra.sweep.dir" if resume else "hydra.run.dir"
            raise (output_error(err, option, lock_path) or err) from None
        if lock is None:
            holder = _lock_holder(lock_path) or "unknown"
            raise ConfigError("", f"{run_dir}: another nlosfw run (process {holder}) is "
                                  "writing there; wait for it to end or choose another directory")
        try:
            earlier = inspect_run_dir(run_dir, planned, check_live=False)
            decision = verdict(run_dir, earlier, config, settings, resume=resume)
            if decision is Verdict.skip:
                _unlock(lock, lock_path, remove=not existed)
                return None
            if decision is Verdict.set_aside:
                _set_aside(run_dir, earlier)
            elif decision is Verdict.replace:
                _remove(run_dir, earlier)
        except BaseException:
            _unlock(lock, lock_path, remove=not existed)
            raise
        lock.seek(0)
        lock.truncate()
        lock.write(f"{os.getpid()}@{socket.gethostname()}\n")
        lock.flush()
        marker = RunMarker(format=MARKER_FORMAT, version=1, pid=os.getpid(),
                           host=socket.gethostname(), config_hash=config_hash(config), files=[])
        return cls(run_dir, lock, marker)

    def claim(self, name: str) -> None:
        """Record ``name`` (relative to the run directory) as this run's, before writing it."""
        if name in self._marker["files"]:
            return
        self._marker = RunMarker(**{**self._marker, "files": [*self._marker["files"], name]})
        write_text(self.run_dir / MARKER_NAME, json.dumps(self._marker, indent=1) + "\n",
                   overwrite=True)

    def release(self) -> None:
        """Drop the lock (and its file); the marker stays for later runs to read."""
        _unlock(self._lock, self.run_dir / LOCK_NAME, remove=True)


def _unlock(handle: IO[str], path: Path, remove: bool) -> None:
    if remove:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    handle.close()  # closing drops the flock


def _lock_holder(path: Path) -> str | None:
    """``pid@host`` of the process holding ``path``'s lock, or None when nobody does."""
    import fcntl

    try:
        handle = open(path)  # noqa: SIM115 - closed below
    except OSError:
        return None
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return handle.read().strip() or "unknown"
        except OSError:
            return None
        fcntl.flock(handle, fcntl.LOCK_UN)
    return None


def _read_marker(path: Path) -> RunMarker | None:
    if not path.is_file():
        return None
    try:
        marker = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise DataError(f"{path}: unreadable run marker; move the directory's files away "
                        "by hand") from None
    if not (isinstance(marker, dict) and marker.get("format") == MARKER_FORMAT
            and isinstance(marker.get("files"), list)):
        raise DataError(f"{path}: not an nlosfw run marker")
    pid = marker.get("pid")
    version = marker.get("version")
    return RunMarker(format=MARKER_FORMAT, version=version if isinstance(version, int) else 1,
                     pid=pid if isinstance(pid, (int, str)) else "",
                     host=str(marker.get("host", "")),
                     config_hash=str(marker.get("config_hash", "")),
                     files=[str(f) for f in marker["files"]])


# ------------------------------------------------------------------- acting on files
def _claimed_paths(run_dir: Path, earlier: EarlierRun) -> list[Path]:
    """The earlier run's files that exist, its temporaries, then its marker, never anything
    outside ``run_dir``."""
    root = run_dir.resolve()
    out = []
    for name in earlier.files:
        path = run_dir / name
        if root in path.resolve().parents and (path.is_file() or path.is_symlink()):
            out.append(path)
    pid = "" if earlier.marker is None else str(earlier.marker["pid"])
    dirs = {run_dir, *((run_dir / name).parent for name in earlier.files)}
    for folder in dirs:
        if not folder.is_dir() or root not in [folder.resolve(), *folder.resolve().parents]:
            continue
        for entry in folder.iterdir():
            match = TEMPORARY_NAME.match(entry.name)
            if match and match.group("pid") == pid and entry.is_file():
                out.append(entry)
    out.append(run_dir / MARKER_NAME)
    return out


def _set_aside(run_dir: Path, earlier: EarlierRun) -> None:
    """Move the earlier (unfinished) run's files into ``interrupted-<time>/``."""
    aside = run_dir / f"interrupted-{time.strftime('%Y%m%d-%H%M%S')}"
    n = 2
    while aside.exists():
        aside = run_dir / f"interrupted-{time.strftime('%Y%m%d-%H%M%S')}-{n}"
        n += 1
    moved = 0
    for path in _claimed_paths(run_dir, earlier):
        target = aside / path.relative_to(run_dir)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(path), target)
        moved += 1
    _remove_empty_parents(run_dir, earlier.files)
    log.warning("moved %d files of an unfinished earlier run to %s", moved, aside)


def _remove(run_dir: Path, earlier: EarlierRun) -> None:
    """Delete the earlier run's files (output.overwrite=true)."""
    paths = _claimed_paths(run_dir, earlier)
    for path in paths:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    _remove_empty_parents(run_dir, earlier.files)
    log.warning("output.overwrite: removed %d files of the earlier run in %s", len(paths),
                run_dir)


def _remove_empty_parents(run_dir: Path, names: Iterable[str]) -> None:
    """Remove the folders the earlier run's files were in, when they are now empty."""
    folders = sorted({(run_dir / n).parent for n in names} - {run_dir},
                     key=lambda p: len(p.parts), reverse=True)
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()  # only ever succeeds on an empty folder


@contextlib.contextmanager
def held(run_dir: Path, config: Mapping[str, object], settings: RunSettings,
         planned: Iterable[str], *, resume: bool) -> Iterator[RunHold | None]:
    """:meth:`RunHold.acquire` for a block, released when it ends (None: skip the run)."""
    hold = RunHold.acquire(run_dir, config, settings, planned, resume=resume)
    try:
        yield hold
    finally:
        if hold is not None:
            hold.release()

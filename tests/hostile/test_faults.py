"""Faults: a full disk, read-only places, SIGINT and SIGTERM, a run that fails late."""

from __future__ import annotations

import errno
import json
import re
import signal
from pathlib import Path

import numpy as np
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import files
from nlosfw.common.errors import StorageError
from nlosfw.pipeline.cache import MARKER_NAME, Cache, cache_entries, file_digest
from nlosfw.pipeline.lifecycle import LOCK_NAME
from nlosfw.testing import fixtures

#: A transient of 32 x 32 sensors and 1024 bins, stored uncompressed: 4.2 MB.
BIG_CAPTURE = ("scene.wall.resolution=[32,32]", "scene.time.bins=1024", "output.compression=0")


def failed_metrics(run: Path) -> dict:
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "failed"
    return metrics


# ------------------------------------------------------------------------ full disk
def test_a_full_disk_at_the_capture_write(workdir, tools, small_disk):
    disk = small_disk(2_500_000)
    result = disk.run(*tools.QUICK, *BIG_CAPTURE, f"hydra.run.dir={disk.path}/run",
                      cwd=workdir)
    assert result.returncode == 1, result.stderr
    line = tools.one_error_line(result)
    assert re.fullmatch(r"error: \S+/run/capture\.hdf5: not enough disk space: writing it "
                        r"needs 4\.\d MB, [12]\.\d MB free", line), line
    run = disk.path / "run"
    assert not (run / "capture.hdf5").exists() and not tools.temporaries(disk.path)
    metrics = failed_metrics(run)
    assert metrics["error"]["stage"] == "capture"
    assert metrics["error"]["message"] == line.removeprefix("error: ")
    # the cache (elsewhere) holds the capture, whole
    (entry,) = [e for e in cache_entries(workdir / "cache") if e.path.parent.name == "captures"]
    assert entry.check.read_text().strip() == file_digest(entry.path)


def test_a_full_disk_at_the_phasor_field_write(workdir, tools, small_disk):
    disk = small_disk(3_000_000)
    result = disk.run(*tools.QUICK, "transform.n_frequencies=2000",
                      "output.keep=[capture,phasor_field]", f"hydra.run.dir={disk.path}/run",
                      cwd=workdir)
    assert result.returncode == 1, result.stderr
    line = tools.one_error_line(result)
    assert re.fullmatch(r"error: \S+/run/phasor_field\.hdf5: not enough disk space: writing it "
                        r"needs 8\.\d MB, 2\.\d MB free", line), line
    run = disk.path / "run"
    assert (run / "capture.hdf5").is_file() and not (run / "phasor_field.hdf5").exists()
    assert not tools.temporaries(disk.path)
    assert failed_metrics(run)["error"]["stage"] == "transform"


def test_a_full_cache_disk_is_skipped_and_the_cache_stays_consistent(workdir, tools,
                                                                     small_disk):
    """Entries that do not fit are not stored (a warning); no partial entry, no crash
    (libhdf5 used to segfault freeing a file whose write had failed)."""
    disk = small_disk(600_000)
    for attempt in range(2):
        result = disk.run(*tools.QUICK, "transform.n_frequencies=200", "stop_after=transform",
                          f"cache.dir={disk.path}", f"hydra.run.dir=run{attempt}", cwd=workdir)
        assert result.returncode == 0, result.stderr
        assert "cache: could not store" in (workdir / f"run{attempt}" / "run.log").read_text()
    entries = cache_entries(disk.path)
    assert [e.path.parent.name for e in entries] == ["captures"]  # the field did not fit
    for entry in entries:
        assert entry.check.read_text().strip() == file_digest(entry.path)
    stray = [p for p in disk.path.rglob("*") if p.is_file() and p.suffix not in (".lock",)
             and p.name != MARKER_NAME
             and p not in {e.path for e in entries} | {e.check for e in entries}]
    assert stray == []
    metrics = json.loads((workdir / "run1" / "metrics.json").read_text())
    assert metrics["capture"]["cache_hit"] is True and metrics["transform"]["cache_hit"] is False


def test_enospc_in_the_middle_of_a_write_on_a_real_small_disk(tmp_path, small_disk,
                                                              monkeypatch):
    """The free-space check passes (another process fills the disk after it): the write
    itself hits ENOSPC, and still ends in one StorageError with nothing left behind."""
    disk = small_disk(1_000_000)
    if disk.mode != "direct":
        pytest.skip("writes in this process need the small disk mounted here (root)")
    monkeypatch.setattr(files, "ensure_free_space", lambda path, size: None)
    capture = fixtures.tiny_capture()
    big = capture.replace(H=np.random.default_rng(0).random((8192, *capture.H.shape[1:]))
                          .astype(np.float32))   # 2 MB, on a 1 MB disk
    with pytest.raises(StorageError, match=r"capture\.hdf5: no space left on device \(it needs "
                                           r"more than the .* written so far; .* free\)"):
        write_capture(disk.path / "capture.hdf5", big)
    assert list(disk.path.iterdir()) == []


class _FullFile:
    """A file whose writes fail with ENOSPC after ``room`` bytes, as on a full disk."""

    def __init__(self, handle, room: int) -> None:
        self.handle, self.room = handle, room

    def write(self, data) -> int:
        if len(data) > self.room:
            self.handle.write(bytes(data[:self.room]))
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.handle.write(data)

    def __getattr__(self, name):
        return getattr(self.handle, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.handle.close()


def test_enospc_injected_at_the_write_calls(tmp_path, monkeypatch):
    """Everywhere (no mount needed): ENOSPC injected into nlosfw's own writes, and raised
    by a plugin's writer (a model file, a figure) inside an atomic write."""
    real_open = open
    monkeypatch.setattr(files, "open", lambda path, mode="r": _FullFile(real_open(path, mode),
                                                                        10_000), raising=False)
    with pytest.raises(StorageError, match=r"capture\.hdf5: no space left on device"):
        write_capture(tmp_path / "capture.hdf5", fixtures.tiny_capture())
    assert list(tmp_path.iterdir()) == []

    def writer(path: Path) -> None:
        with real_open(path, "wb") as fh:
            fh.write(b"x" * 5000)
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    expected = r"model\.npz: no space left on device \(it needs more than the 5\.0 kB written"
    with pytest.raises(StorageError, match=expected), files.atomic_path(
            tmp_path / "model.npz") as tmp:
        writer(tmp)
    assert list(tmp_path.iterdir()) == []


def test_enospc_injected_into_a_cache_write_leaves_no_entry(tmp_path, monkeypatch):
    real_open = open
    monkeypatch.setattr(files, "open", lambda path, mode="r": _FullFile(real_open(path, mode),
                                                                        1000), raising=False)
    cache = Cache(tmp_path)
    capture = fixtures.tiny_capture()
    value, hit = cache.get_or_compute("captures", "0" * 64, lambda: capture, write_capture,
                                      read_capture)
    assert value is capture and not hit
    assert sorted(p.name for p in (tmp_path / "captures").iterdir()) == [f"{'0' * 64}.lock"]


# ------------------------------------------------------------------------ read-only
def test_a_read_only_output_directory_is_refused_before_anything(workdir, tools,
                                                                 read_only_dir):
    for flags, args in (((), (f"hydra.run.dir={read_only_dir}/run",)),
                        (("-m",), ("model=interp,nearest",
                                   f"hydra.sweep.dir={read_only_dir}/sweep"))):
        result = tools.run(*flags, *tools.QUICK, *args)
        assert result.returncode == 2
        key = "hydra.sweep.dir" if flags else "hydra.run.dir"
        assert re.fullmatch(
            rf"error: {key}: {read_only_dir} cannot be written \((read-only file system|"
            r"permission denied)\); choose another output directory",
            tools.one_error_line(result)), result.stderr
    assert list(read_only_dir.iterdir()) == [] and not (workdir / "cache").exists()


def test_a_read_only_cache_disables_the_cache_with_a_warning(workdir, tools, read_only_dir):
    result = tools.run(*tools.QUICK, f"cache.dir={read_only_dir}", "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    log = (workdir / "run" / "run.log").read_text()
    assert f"cache: {read_only_dir} is not writable" in log and "running without the cache" in log
    assert json.loads((workdir / "run" / "metrics.json").read_text())["status"] == "completed"


# -------------------------------------------------------------------------- signals
@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                             (signal.SIGHUP, 129)])
def test_a_signal_stops_the_run_cleanly(workdir, tools, sig, status):
    """The run is held with capture.hdf5 written at its temporary path, not yet published:
    the signal removes the temporary and records where the run stopped."""
    run = workdir / "run"
    proc, pause = tools.start_held("capture.hdf5", *tools.QUICK, "hydra.run.dir=run",
                                   cwd=workdir)
    tools.wait_held(pause, proc)
    assert [p.suffix for p in tools.temporaries(run)] == [".hdf5"]   # mid-write
    code, out, err = tools.stop(proc, sig)
    assert code == status, err
    name = signal.Signals(sig).name
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines == [f"interrupted by {name}: stopped cleanly (exit status {status})"], err
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "interrupted"
    assert metrics["error"] == {"stage": "capture", "message": f"interrupted by {name}",
                                "signal": name}
    assert not (run / LOCK_NAME).exists()
    assert not tools.temporaries(run) and not tools.temporaries(workdir / "cache")


# ----------------------------------------------------------------------- late errors
def test_a_run_that_fails_late_says_where_and_why(workdir, tools):
    result = tools.run(*tools.QUICK[:1], "model=siren_torch", "model.lr=1e4", "model.steps=200",
                       *tools.QUICK[2:], "hydra.run.dir=run")
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert line.startswith("error: siren_torch: training diverged at step ")
    metrics = failed_metrics(workdir / "run")
    assert metrics["error"] == {"stage": "fit", "message": line.removeprefix("error: ")}
    assert metrics["timings"]["capture"] > 0 and "fit" not in metrics["timings"]
    assert not tools.temporaries(workdir / "run")

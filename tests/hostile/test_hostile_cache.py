"""The cache owns only what it wrote: a folder of the user's files is never
cleaned, foreign files inside a cache are never touched, odd files in an entry's place
(a directory, a FIFO) never hang or crash a run, and ``output.overwrite`` never removes
a file the new run reads."""

from __future__ import annotations

import json
import math
import os
import threading
from pathlib import Path

import pytest

from nlosfw.common.errors import ConfigError
from nlosfw.pipeline import lifecycle
from nlosfw.pipeline.cache import MARKER_NAME, Cache, cache_entries, claim, clean_cache, owns

KEY_A, KEY_B = "a" * 64, "b" * 64


def put(cache: Cache, key: str, kind: str = "blobs") -> tuple[bytes, bool]:
    return cache.get_or_compute(kind, key, lambda: key.encode() * 10,
                                lambda p, v: p.write_bytes(v), lambda p: p.read_bytes())


def in_thread(call, timeout: float = 120.0):
    """``call()`` in a thread, failing (not hanging) when it has not returned in time."""
    out: list[object] = []
    thread = threading.Thread(target=lambda: out.append(call()), daemon=True)
    thread.start()
    thread.join(timeout)
    assert not thread.is_alive(), f"the call did not return within {timeout} s (it hangs)"
    return out[0]


def user_folder(root: Path) -> Path:
    """A folder of a user's measurements (no cache marker)."""
    (root / "scans").mkdir(parents=True)
    (root / "scans" / "my_measurement.hdf5").write_bytes(b"precious")
    (root / "scans" / "notes.txt").write_text("lab book")
    return root


# --------------------------------------------------------------------- ownership
def test_cache_clean_on_a_users_folder_deletes_nothing(workdir, tools):
    folder = user_folder(workdir / "data")
    result = tools.run("cache", "clean", "--dir", str(folder))
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert line.startswith(f"error: --dir: {folder} is not an nlosfw cache")
    assert "nothing was removed" in line
    assert (folder / "scans" / "my_measurement.hdf5").read_bytes() == b"precious"
    assert not (folder / MARKER_NAME).exists()
    assert clean_cache(folder) == (0, 0, 0)
    assert (folder / "scans" / "my_measurement.hdf5").exists()


def test_a_run_never_uses_nor_evicts_from_a_users_folder(tmp_path, caplog):
    folder = user_folder(tmp_path / "data")
    cache = Cache(folder, max_gb=0)                 # evict everything it can
    value, hit = put(cache, KEY_A)
    assert value == KEY_A.encode() * 10 and not hit
    assert "holds files nlosfw did not write" in caplog.text
    assert sorted(p.name for p in folder.rglob("*")) == ["my_measurement.hdf5", "notes.txt",
                                                          "scans"]


def test_foreign_files_inside_a_cache_are_not_entries(tmp_path):
    cache = Cache(tmp_path / "cache", max_gb=0)
    put(cache, KEY_A)
    kind = tmp_path / "cache" / "blobs"
    (kind / "my_measurement.hdf5").write_bytes(b"precious")     # not a key
    (kind / f"{KEY_B}.hdf5").write_bytes(b"no checksum")        # a key without its .sha256
    assert [e.path.name for e in cache_entries(tmp_path / "cache")] == [f"{KEY_A}.hdf5"]
    assert clean_cache(tmp_path / "cache")[0] == 1
    assert sorted(p.name for p in kind.iterdir()) == [f"{KEY_B}.hdf5", "my_measurement.hdf5"]


def test_an_older_cache_without_a_marker_is_adopted(tmp_path):
    root = tmp_path / "old"
    (root / "blobs").mkdir(parents=True)
    for key in (KEY_A, KEY_B):
        (root / "blobs" / f"{key}.hdf5").write_bytes(b"x" * 10)
        (root / "blobs" / f"{key}.sha256").write_text("0" * 64 + "\n")
    assert not owns(root)
    assert clean_cache(root) == (2, 2 * (10 + 65), 0)
    assert owns(root) and json.loads((root / MARKER_NAME).read_text())["format"] == "nlosfw-cache"


def test_a_folder_with_one_foreign_file_is_not_adopted(tmp_path):
    root = tmp_path / "old"
    (root / "blobs").mkdir(parents=True)
    (root / "blobs" / f"{KEY_A}.hdf5").write_bytes(b"x")
    (root / "blobs" / f"{KEY_A}.sha256").write_text("0" * 64)
    (root / "blobs" / "thesis.hdf5").write_bytes(b"y")
    assert not claim(root, adopt_only=True) and not owns(root)
    assert clean_cache(root) == (0, 0, 0)
    assert len(list((root / "blobs").iterdir())) == 3


def test_a_run_directory_inside_the_cache_is_refused(workdir, tools):
    result = tools.run(*tools.QUICK, f"cache.dir={workdir / 'cache'}",
                       f"hydra.run.dir={workdir / 'cache' / 'run'}")
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert line.startswith(f"error: hydra.run.dir: {workdir / 'cache' / 'run'} is inside the "
                           "cache directory")
    assert "cache.dir" in line
    assert not (workdir / "cache" / "run").exists()


# ------------------------------------------------------------------- odd values
def test_max_gb_inf_means_no_limit(tmp_path):
    from nlosfw.pipeline.settings import CacheSettings

    assert CacheSettings(max_gb=math.inf).max_gb == math.inf
    cache = Cache(tmp_path, max_gb=math.inf)
    assert cache.max_bytes is None
    put(cache, KEY_A)
    put(cache, KEY_B)
    assert len(cache_entries(tmp_path)) == 2


def test_max_gb_inf_on_the_command_line_keeps_every_entry(workdir, tools):
    """``cache.max_gb=inf`` (YAML's .inf) through Hydra: the run completes and evicts nothing
    (its capture and field entries stay); ``cache clean --keep-gb inf`` keeps them too."""
    cache = workdir / "cache"
    result = tools.run(*tools.QUICK, "cache.max_gb=inf", "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    assert json.loads((workdir / "run" / "metrics.json").read_text())["status"] == "completed"
    entries = sorted(entry.path for entry in cache_entries(cache))
    assert entries
    cleaned = tools.run("cache", "clean", "--dir", str(cache), "--keep-gb", "inf")
    assert cleaned.returncode == 0, cleaned.stderr
    assert sorted(entry.path for entry in cache_entries(cache)) == entries


@pytest.mark.parametrize("keep", ["nan", "-inf"])
def test_keep_gb_not_a_size_is_one_line(workdir, tools, keep):
    result = tools.run("cache", "clean", f"--keep-gb={keep}")
    assert result.returncode == 2
    assert tools.one_error_line(result) == f"error: --keep-gb: must be >= 0, got {float(keep)}"


def test_keep_gb_inf_keeps_every_entry(workdir, tools):
    put(Cache(workdir / "cache"), KEY_A)
    result = tools.run("cache", "clean", "--keep-gb", "inf")
    assert result.returncode == 0, result.stderr
    assert len(cache_entries(workdir / "cache")) == 1


@pytest.mark.parametrize("what", ["entry", "checksum", "lock"])
@pytest.mark.parametrize("odd", ["directory", "fifo"])
def test_an_odd_file_in_an_entrys_place_neither_hangs_nor_fails(tmp_path, what, odd):
    root = tmp_path / "cache"
    put(Cache(root), KEY_A)
    suffix = {"entry": ".hdf5", "checksum": ".sha256", "lock": ".lock"}[what]
    target = root / "blobs" / f"{KEY_A}{suffix}"
    target.unlink(missing_ok=True)
    if odd == "directory":
        target.mkdir()
        (target / "inside").write_text("kept")
    else:
        os.mkfifo(target)
    value, hit = in_thread(lambda: put(Cache(root), KEY_A))
    assert value == KEY_A.encode() * 10 and not hit
    in_thread(lambda: clean_cache(root))            # never opens it either
    assert target.is_dir() if odd == "directory" else target.is_fifo()
    if what != "lock":  # an odd lock leaves the entry an entry, but never evicted
        assert cache_entries(root) == []


def test_cache_info_and_clean_beside_a_fifo(workdir, tools):
    root = workdir / "cache"
    put(Cache(root), KEY_A)
    os.mkfifo(root / "blobs" / f"{KEY_B}.hdf5")
    info = in_thread(lambda: tools.run("cache", "info", "--dir", str(root)))
    assert info.returncode == 0 and info.stdout.startswith(f"cache {root}: 1 entries")
    assert in_thread(lambda: tools.run("cache", "clean", "--dir", str(root))).returncode == 0
    assert (root / "blobs" / f"{KEY_B}.hdf5").is_fifo()


@pytest.mark.malformed_metrics
def test_a_fifo_named_metrics_json_given_to_report_does_not_hang(workdir, tools):
    runs = workdir / "runs"
    (runs / "job").mkdir(parents=True)
    os.mkfifo(runs / "job" / "metrics.json")
    result = in_thread(lambda: tools.run("report", str(runs)))
    assert result.returncode == 2
    assert "no metrics.json" in tools.one_error_line(result)


@pytest.mark.malformed_metrics
def test_a_fifo_metrics_json_is_not_read(tmp_path):
    from nlosfw.common.errors import DataError
    from nlosfw.pipeline.metrics import RunMetrics

    os.mkfifo(tmp_path / "metrics.json")
    err = in_thread(lambda: _raised(lambda: RunMetrics.read(tmp_path / "metrics.json")))
    assert isinstance(err, DataError) and "not a regular file" in str(err)


def _raised(call):
    """The exception ``call()`` raised, or None."""
    try:
        call()
    except Exception as err:
        return err
    return None


# ----------------------------------------------------------------- overwrite
def earlier_run(run_dir: Path, files: dict[str, bytes]) -> None:
    """A finished earlier run in ``run_dir`` that claimed ``files``."""
    run_dir.mkdir(parents=True)
    for name, data in files.items():
        (run_dir / name).write_bytes(data)
    (run_dir / lifecycle.MARKER_NAME).write_text(json.dumps(
        {"format": lifecycle.MARKER_FORMAT, "version": 1, "pid": 1, "host": "h",
         "config_hash": "", "files": sorted(files)}))


@pytest.mark.parametrize("option", ["capture.path", "capture.background", "capture.tofgrid"])
def test_overwrite_refuses_to_remove_an_input_of_the_new_run(tmp_path, option):
    from nlosfw.pipeline.settings import run_settings

    run = tmp_path / "run"
    earlier_run(run, {"capture.hdf5": b"the capture", "config.yaml": b"{}"})
    section, leaf = option.split(".")
    config = {section: {leaf: str(run / "capture.hdf5")}, "cache": {"dir": str(tmp_path / "c")},
              "output": {"overwrite": True}}
    earlier = lifecycle.inspect_run_dir(run, ())
    with pytest.raises(ConfigError) as caught:
        lifecycle.verdict(run, earlier, config, run_settings(config), resume=False)
    assert caught.value.option == option
    assert "output.overwrite=true would remove" in str(caught.value)
    link = tmp_path / "elsewhere.hdf5"                 # the same file by another name
    os.link(run / "capture.hdf5", link)
    config = {section: {leaf: str(link)}, "output": {"overwrite": True}}
    with pytest.raises(ConfigError):
        lifecycle.verdict(run, earlier, config, run_settings(config), resume=False)
    assert (run / "capture.hdf5").read_bytes() == b"the capture"


def test_overwrite_of_a_run_whose_capture_is_read_is_refused_end_to_end(workdir, tools):
    from nlosfw.capture.hdf5 import write_capture
    from nlosfw.testing import fixtures

    run = workdir / "run"
    earlier_run(run, {"config.yaml": b"{}"})
    write_capture(run / "capture.hdf5", fixtures.tiny_capture())
    marker = json.loads((run / lifecycle.MARKER_NAME).read_text())
    marker["files"].append("capture.hdf5")
    (run / lifecycle.MARKER_NAME).write_text(json.dumps(marker))
    before = (run / "capture.hdf5").read_bytes()
    result = tools.run("model=interp", "imager=fft", "figures.enabled=false",
                       "transform.n_frequencies=21", "reconstruction.n_depths=4",
                       f"capture.path={run / 'capture.hdf5'}", f"hydra.run.dir={run}",
                       "output.overwrite=true")
    assert result.returncode == 2, result.stderr
    assert tools.one_error_line(result).startswith(f"error: capture.path: {run / 'capture.hdf5'}"
                                                   " is a file of the earlier run")
    assert (run / "capture.hdf5").read_bytes() == before

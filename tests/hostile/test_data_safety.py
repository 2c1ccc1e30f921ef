"""Data is never lost or moved: a user's files, a finished run, a live run, a resumed sweep."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest

from nlosfw.pipeline.lifecycle import LOCK_NAME, MARKER_NAME


def snapshot(root: Path, skip: tuple[str, ...] = ()) -> dict[str, bytes]:
    """Every file under ``root`` (relative path -> bytes), leaving out names in ``skip``."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and not any(part in skip for part in p.relative_to(root).parts)}


def user_files(root: Path) -> dict[str, bytes]:
    files = {"notes.txt": b"my notes\n", "data/measurement.bin": os.urandom(256),
             "figures/mine.png": b"\x89PNG not really"}
    for name, data in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    return files


def test_a_users_files_in_the_run_directory_are_never_moved(workdir, tools):
    """hydra.run.dir=. in a folder of the user's: refused where its files are in the way,
    and where nothing is in the way the run adds its files and touches nothing else."""
    mine = user_files(workdir)
    refused = tools.run(*tools.QUICK, "hydra.run.dir=.")
    assert refused.returncode == 2
    assert tools.one_error_line(refused) == (
        f"error: {workdir}: holds figures, which no nlosfw run wrote there; choose another "
        "directory (nothing was changed)")
    (workdir / "figures" / "mine.png").unlink()
    (workdir / "figures").rmdir()
    del mine["figures/mine.png"]
    (workdir / "run.log").write_text("my own log\n")   # Hydra would append to it
    refused = tools.run(*tools.QUICK, "hydra.run.dir=.")
    assert tools.one_error_line(refused) == (
        f"error: {workdir}: holds run.log, which no nlosfw run wrote there; choose another "
        "directory (nothing was changed)")
    assert (workdir / "run.log").read_text() == "my own log\n"
    (workdir / "run.log").unlink()
    before = sorted(p.name for p in workdir.iterdir())
    assert before == ["data", "notes.txt"]  # nothing was created by the refused runs

    done = tools.run(*tools.QUICK, "hydra.run.dir=.")
    assert done.returncode == 0, done.stderr
    for name, data in mine.items():
        assert (workdir / name).read_bytes() == data
    assert not list(workdir.glob("interrupted-*"))
    marker = json.loads((workdir / MARKER_NAME).read_text())
    assert "notes.txt" not in marker["files"] and "capture.hdf5" in marker["files"]
    assert json.loads((workdir / "metrics.json").read_text())["status"] == "completed"


def test_a_second_run_in_a_finished_runs_directory(workdir, tools):
    """Refused (exit 2, one line, nothing changed) unless output.overwrite=true, which
    replaces only the earlier run's own files."""
    user_files(workdir / "run")
    (workdir / "run" / "figures" / "mine.png").unlink()
    (workdir / "run" / "figures").rmdir()
    first = tools.run(*tools.QUICK, "hydra.run.dir=run")
    assert first.returncode == 0, first.stderr
    run = workdir / "run"
    before = snapshot(run, skip=("run.log",))

    again = tools.run(*tools.QUICK, "hydra.run.dir=run")
    assert again.returncode == 2
    assert tools.one_error_line(again) == (
        f"error: output.overwrite: {run} already holds a completed run; choose another "
        "directory, or set output.overwrite=true to replace its files")
    assert snapshot(run, skip=("run.log",)) == before     # .hydra/ included: untouched
    shown = tools.run("--cfg", "job", *tools.QUICK, "hydra.run.dir=run")  # runs nothing
    assert shown.returncode == 0 and "name: interp" in shown.stdout

    replaced = tools.run(*tools.QUICK, "hydra.run.dir=run", "output.overwrite=true")
    assert replaced.returncode == 0, replaced.stderr
    after = snapshot(run, skip=("run.log",))
    assert after["notes.txt"] == before["notes.txt"]
    assert after["data/measurement.bin"] == before["data/measurement.bin"]
    assert json.loads(after["metrics.json"])["run"]["started"] >= json.loads(
        before["metrics.json"])["run"]["started"]
    assert set(after) == set(before) and not list(run.glob("interrupted-*"))


def test_a_live_run_is_refused_and_its_files_untouched(workdir, tools):
    """Two more runs try the directory of a run held in its capture stage: both refused,
    the held run undisturbed (it then stops on SIGTERM, as any run does)."""
    run = workdir / "run"
    proc, pause = tools.start_held("capture", *tools.QUICK, "hydra.run.dir=run", cwd=workdir)
    try:
        tools.wait_held(pause, proc)
        before = snapshot(run, skip=("run.log",))
        lock_text = (run / LOCK_NAME).read_text().strip()
        assert lock_text.startswith(f"{proc.pid}@")
        for extra in ((), ("output.overwrite=true",)):
            second = tools.run(*tools.QUICK, "hydra.run.dir=run", *extra)
            assert second.returncode == 2
            assert tools.one_error_line(second) == (
                f"error: {run}: another nlosfw run (process {lock_text}) is writing there; "
                "wait for it to end or choose another directory")
            assert snapshot(run, skip=("run.log",)) == before
        assert proc.poll() is None  # still held, undisturbed
    finally:
        status, _, err = tools.stop(proc, signal.SIGTERM)
    assert status == 143, err


def test_kill_9_leaves_no_partial_file_and_the_directory_is_not_reused_silently(workdir, tools):
    run = workdir / "run"
    proc, pause = tools.start_held("capture", *tools.QUICK, "hydra.run.dir=run", cwd=workdir)
    tools.wait_held(pause, proc)
    proc.send_signal(signal.SIGKILL)
    tools.finish(proc)
    assert not tools.temporaries(run)
    assert not (run / "capture.hdf5").exists() and not (run / "metrics.json").exists()
    marker = json.loads((run / MARKER_NAME).read_text())
    assert marker["pid"] == proc.pid and marker["files"] == ["config.yaml"]

    again = tools.run(*tools.QUICK, "hydra.run.dir=run")
    assert again.returncode == 2
    assert tools.one_error_line(again) == (
        f"error: output.overwrite: {run} already holds an unfinished run; choose another "
        "directory, or set output.overwrite=true to replace its files")
    replaced = tools.run(*tools.QUICK, "hydra.run.dir=run", "output.overwrite=true")
    assert replaced.returncode == 0, replaced.stderr
    assert json.loads((run / "metrics.json").read_text())["status"] == "completed"
    assert not (run / LOCK_NAME).exists() and not tools.temporaries(run)


SWEEP = ("-m", "scene=tiny", "model=interp,nearest", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=21", "reconstruction.n_depths=4")


def test_a_resumed_sweep_skips_a_finished_job_only_for_the_same_configuration(workdir, tools):
    sweep = workdir / "sweep"
    first = tools.run(*SWEEP, f"hydra.sweep.dir={sweep}")
    assert first.returncode == 0, first.stderr
    before = snapshot(sweep, skip=("run.log", "multirun.yaml"))

    changed = tools.run(*SWEEP, "reconstruction.n_depths=5", f"hydra.sweep.dir={sweep}")
    assert changed.returncode == 2
    assert tools.one_error_line(changed) == (
        f"error: reconstruction.n_depths: is 5 but 4 in the run in {sweep / '0'}; this sweep "
        "directory was run with another configuration; use a new hydra.sweep.dir, or "
        "output.overwrite=true to replace its runs")
    assert snapshot(sweep, skip=("run.log", "multirun.yaml")) == before  # .hydra/ too

    # run-control options (where the cache is, whether to use it) do not change results
    same = tools.run(*SWEEP, "cache.enabled=false", f"hydra.sweep.dir={sweep}")
    assert same.returncode == 0 and same.stdout.count("skipping") == 2, same.stdout
    assert snapshot(sweep, skip=("run.log", "multirun.yaml", ".hydra")) == {
        k: v for k, v in before.items() if "/.hydra/" not in f"/{k}"}

    # an unfinished job is set aside (its own files only) and run again
    (sweep / "1" / "metrics.json").unlink()
    resumed = tools.run(*SWEEP, f"hydra.sweep.dir={sweep}")
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stdout.count("skipping") == 1
    (aside,) = (sweep / "1").glob("interrupted-*")
    assert (aside / "capture.hdf5").is_file() and (aside / MARKER_NAME).is_file()
    assert json.loads((sweep / "1" / "metrics.json").read_text())["status"] == "completed"


def test_a_hostile_marker_cannot_reach_outside_its_directory(workdir, tools):
    """A marker naming ../victim (or an absolute path) never makes a run remove it."""
    victim = workdir / "victim.txt"
    victim.write_text("keep me")
    run = workdir / "run"
    run.mkdir()
    (run / MARKER_NAME).write_text(json.dumps({
        "format": "nlosfw-run", "version": 1, "pid": 1, "host": "x", "config_hash": "0",
        "files": ["../victim.txt", str(victim), "config.yaml"]}))
    result = tools.run(*tools.QUICK, "hydra.run.dir=run", "output.overwrite=true")
    assert result.returncode == 0, result.stderr
    assert victim.read_text() == "keep me"


@pytest.mark.parametrize("broken", ["{not json", json.dumps({"format": "other", "files": []})])
def test_an_unreadable_marker_is_refused_not_guessed(workdir, tools, broken):
    run = workdir / "run"
    run.mkdir()
    (run / MARKER_NAME).write_text(broken)
    result = tools.run(*tools.QUICK, "hydra.run.dir=run")
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith(f"error: {run / MARKER_NAME}: ")
    assert sorted(p.name for p in run.iterdir()) == [MARKER_NAME]

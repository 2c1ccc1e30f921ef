"""One-line errors where tracebacks were, SIGHUP, and two threads running at once."""

from __future__ import annotations

import json
import signal
import threading
from pathlib import Path

import pytest

from nlosfw.common.errors import RunInterrupted
from nlosfw.pipeline.interrupts import SIGNALS, as_interruption

#: The quick run stopped after the capture: the cheapest run that writes metrics.json.
CAPTURE_ONLY = ("scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
                "transform.n_frequencies=21", "reconstruction.n_depths=4", "stop_after=capture")


def test_experimental_rerun_is_refused(workdir, tools):
    (workdir / "config.pickle").write_bytes(b"cos\nsystem\n(S'touch pwned'\ntR.")
    result = tools.run("--experimental-rerun", str(workdir / "config.pickle"))
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith("error: --experimental-rerun is not "
                                                   "supported: it unpickles a file")
    assert not (workdir / "pwned").exists()


@pytest.mark.parametrize(("override", "message"), [
    ("+a=" + "{b:" * 500 + "1" + "}" * 500, "error: a: its value is nested 500 levels deep"),
    ("+" + ".".join(["k"] * 3000) + "=1", "error: command line: the key +k.k.k"),
    ("hydra.run.dir=" + "x" * 300, "error: hydra.run.dir: the name xxx"),
])
def test_monstrous_overrides_are_one_line(workdir, tools, override, message):
    result = tools.run(*CAPTURE_ONLY, override)
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith(message)


def test_a_dangling_symlink_as_the_run_directory_is_one_line(workdir, tools):
    (workdir / "run").symlink_to(workdir / "nowhere" / "at-all")
    result = tools.run(*CAPTURE_ONLY, f"hydra.run.dir={workdir / 'run'}")
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: hydra.run.dir: {workdir / 'run'} is a link to {workdir / 'nowhere' / 'at-all'}, "
        "which does not exist; remove the link or choose another directory")
    assert not (workdir / "nowhere").exists()


def test_sighup_is_an_interruption_with_status_129():
    assert signal.SIGHUP in SIGNALS
    err = as_interruption(RunInterrupted(signal.SIGHUP))
    assert err is not None and err.exit_status == 128 + 1 and err.signal_name == "SIGHUP"


def test_an_unexpected_failure_in_a_stage_is_recorded_and_one_line(workdir, tools,
                                                                    monkeypatch):
    """A bug (here a TypeError raised by the transform stage) ends as status failed with
    the stage in metrics.json, one line on the console, exit status 1, the lock released
    and the traceback in run.log."""
    from nlosfw.pipeline import engine
    from nlosfw.pipeline.lifecycle import LOCK_NAME

    def broken(*args, **kwargs):
        raise TypeError("a bug in a stage")

    stages = tuple(engine.Stage(s.name, broken) if s.name == "transform" else s
                   for s in engine.STAGES)
    monkeypatch.setattr(engine, "STAGES", stages)
    run = workdir / "run"
    result = tools.run(*CAPTURE_ONLY, "stop_after=transform", f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    line = tools.one_error_line(result)
    assert line.startswith("error: TypeError: a bug in a stage (an unexpected failure in "
                           "stage transform;")
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "failed"
    assert metrics["error"]["stage"] == "transform"
    assert metrics["error"]["message"] == "TypeError: a bug in a stage"
    assert not (run / LOCK_NAME).exists()
    assert "Traceback" in (run / "run.log").read_text()


def test_an_unexpected_failure_shows_its_traceback_with_debug(workdir, tools, monkeypatch):
    from nlosfw.cli import commands

    def broken(args):
        raise KeyError("deep inside")

    monkeypatch.setattr(commands, "_dispatch", broken)
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.setenv("NLOSFW_DEBUG", "0")    # restored (unset) after the test: --debug sets it
    plain = tools.run("anything")
    assert plain.returncode == 1
    assert tools.one_error_line(plain).startswith("error: KeyError: 'deep inside'")
    debug = tools.run("--debug", "anything")
    assert debug.returncode == 1 and "Traceback" in debug.stderr


def test_two_threads_run_at_once(tmp_path, monkeypatch):
    """Used to fail with "OutputSettings is not a subclass of OutputSettings": config
    classes made twice, and Hydra's global session torn down under the other thread."""
    import nlosfw
    from nlosfw.common import schema

    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    schema._twin.cache_clear()  # the twins are made again, by both threads at once
    outcomes: dict[int, object] = {}

    def go(i: int) -> None:
        try:
            outcomes[i] = nlosfw.run(list(CAPTURE_ONLY), output_dir=tmp_path / f"run{i}")
        except Exception as err:
            outcomes[i] = err

    threads = [threading.Thread(target=go, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(600)
    assert not any(t.is_alive() for t in threads), "a run did not end within 600 s"
    for i in range(2):
        out = outcomes[i]
        assert not isinstance(out, Exception), repr(out)
        assert out.metrics.status == "stopped"
        assert json.loads(Path(out.dir, "metrics.json").read_text())["status"] == "stopped"


def test_enospc_in_hydras_own_writes_is_one_line(workdir, tools, monkeypatch):
    import errno

    from hydra.core import utils

    def full(cfg, filename, output_dir):
        path = Path(output_dir) / filename
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(utils, "_save_config", full)
    run = workdir / "run"
    result = tools.run(*CAPTURE_ONLY, f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    assert tools.one_error_line(result).startswith(
        f"error: {run / '.hydra' / 'config.yaml'}: no space left on device")

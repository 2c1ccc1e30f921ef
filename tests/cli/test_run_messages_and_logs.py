"""What a run says and where its log records go: a stop_after run says after which stage it
stopped; the conformance kit without pytest is one line; a run from Python hands its
callers only warnings, and two runs in two threads each log to their own run.log."""

from __future__ import annotations

import subprocess
import sys

import pytest

from nlosfw.cli import main


def test_a_stop_after_run_says_after_which_stage(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["scene=tiny", "stop_after=transform", f"hydra.run.dir={tmp_path / 'run'}"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "done (stopped after transform)" in out


def test_the_kit_without_pytest_is_one_line(tmp_path):
    # a module named pytest that cannot be imported, first on the path
    (tmp_path / "pytest").mkdir()
    (tmp_path / "pytest" / "__init__.py").write_text("raise ModuleNotFoundError('no pytest')\n")
    hide = ("import sys; sys.path.insert(0, sys.argv.pop(1)); sys.argv[0] = 'nlosfw.testing'; "
            "import runpy; runpy.run_module('nlosfw.testing', run_name='__main__')")
    done = subprocess.run([sys.executable, "-c", hide, str(tmp_path), "imager:fft"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "needs pytest" in lines[0], done.stderr


def test_run_from_python_hands_only_warnings_to_the_callers_handlers(tmp_path, monkeypatch):
    """A notebook's root handler (at INFO) sees no INFO line of the run; run.log has them."""
    import logging

    import nlosfw

    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    seen: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            seen.append(record)

    root = logging.getLogger()
    keep, level = Keep(logging.INFO), root.level
    root.addHandler(keep)
    root.setLevel(logging.INFO)
    try:
        out = nlosfw.run(["scene=tiny", "stop_after=transform",
                          "transform.f_max=20"],              # past the aliasing limit: a warning
                         output_dir=tmp_path / "run")
    finally:
        root.removeHandler(keep)
        root.setLevel(level)
    mine = [r for r in seen if r.name.startswith("nlosfw")]
    assert mine and all(r.levelno >= logging.WARNING for r in mine)
    assert "INFO" in (out.dir / "run.log").read_text()
    assert logging.getLogger("nlosfw").propagate


@pytest.mark.parametrize("first_to_end", [0, 1])
def test_runs_in_two_threads_leave_the_loggers_settings_as_they_were(tmp_path, first_to_end):
    """Two overlapping runs' log routing, ended in either order: the nlosfw logger propagates
    again with its old level, and each run.log holds only its own thread's records."""
    import logging
    import threading

    from nlosfw.compose.inprocess import _run_log

    logger = logging.getLogger("nlosfw")
    before = (logger.level, logger.propagate, list(logger.handlers))
    inside = [threading.Event(), threading.Event()]
    leave = [threading.Event(), threading.Event()]
    errors: list[BaseException] = []

    def run(i: int) -> None:
        try:
            with _run_log(tmp_path / f"run{i}.log"):
                logging.getLogger("nlosfw.test").info("record of run %d", i)
                inside[i].set()
                if not leave[i].wait(60):
                    raise TimeoutError(f"run {i} was not told to end within 60 s")
        except BaseException as err:  # handed to the main thread's assertion below
            errors.append(err)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for i, thread in enumerate(threads):
        thread.start()
        assert inside[i].wait(60), f"run {i} did not start logging within 60 s"
    order = [first_to_end, 1 - first_to_end]
    for i in order:
        leave[i].set()
        threads[i].join(60)
        assert not threads[i].is_alive(), f"run {i} did not end within 60 s"
    assert not errors, errors
    assert (logger.level, logger.propagate, list(logger.handlers)) == before
    for i in range(2):
        text = (tmp_path / f"run{i}.log").read_text()
        assert f"record of run {i}" in text and f"record of run {1 - i}" not in text

"""Smaller points of issue 21 on the command line: a stop_after run says after which stage it
stopped; the conformance kit without pytest is one line."""

from __future__ import annotations

import subprocess
import sys

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

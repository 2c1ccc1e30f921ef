"""The README's Install block is two commands, and CI runs exactly them: ``python3 dev.py
run`` (set up, the default run) and ``python3 dev.py test`` (set up with the test tools,
then lint, types and the whole suite). dev.py installs every distribution of the
repository, never CUDA unless asked, and reinstalls only what changed."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / ".ci"


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def dev():
    return _module("nlosfw_dev_script", ROOT / "dev.py")


def _block(section: str) -> str:
    out = subprocess.run([sys.executable, str(CI / "readme_block.py"), section],
                         capture_output=True, text=True, check=True, timeout=60)
    return out.stdout


def _commands(block: str) -> list[list[str]]:
    """The block's commands as argument lists (continuations joined, comments dropped)."""
    joined = block.replace("\\\n", " ")
    return [shlex.split(line, comments=True) for line in joined.splitlines()
            if shlex.split(line, comments=True)]


def test_the_extractor_takes_the_first_bash_block_of_a_section():
    text = ("# T\n\n## Install\n\ntext\n\n```bash\npip install a \\\n  b\n```\n\n```bash\nno\n```"
            "\n\n## Installing more\n\n```bash\nwrong\n```\n## Tests\n```bash\npytest\n```\n")
    extract = _module("readme_block", CI / "readme_block.py").readme_block
    assert extract(text, "Install") == "pip install a \\\n  b\n"
    assert extract(text, "Tests") == "pytest\n"
    for missing in ("Run", "Install more"):
        with pytest.raises(LookupError, match="no section"):
            extract(text, missing)


def test_the_install_block_is_the_two_commands():
    assert _commands(_block("Install")) == [["python3", "dev.py", "run"],
                                            ["python3", "dev.py", "test"]]


def test_dev_test_runs_the_readme_tests_block(dev):
    """Lint, type check and the whole suite: no paths, no -k/-m selection."""
    commands = _commands(_block("Tests"))
    assert commands == [["ruff", "check", "."], ["mypy"], list(dev.PYTEST)]
    assert not {"-k", "-m", "-x"} & set(dev.PYTEST)
    assert dev.CORE_EXTRAS["test"] == ("sweeps", "test") and dev.CORE_EXTRAS["run"] == ("sweeps",)


def test_dev_installs_every_distribution_of_the_repository(dev):
    found = dev.distributions()
    expected = {"."} | {p.parent.relative_to(ROOT).as_posix()
                        for pattern in ("plugins/*/pyproject.toml", "examples/*/pyproject.toml")
                        for p in ROOT.glob(pattern)}
    assert len(expected) >= 8 and set(found) == expected and next(iter(found)) == "."
    names = {dev.project_name(path) for path in found.values()}
    assert {"nlosfw", "nlosfw-torch", "nlosfw-mitsuba", "nlosfw-example-network"} <= names
    assert dev.torch_pin() == "torch==2.13.0"


def test_ci_runs_the_readme_install_block_and_no_install_or_test_command_of_its_own():
    script = (CI / "run").read_text()
    code = [line.split("#", 1)[0] for line in script.splitlines()]
    assert "readme Install" in script and "readme Tests" not in script
    assert "NLOSFW_REQUIRE_SYSTEM=1" in script and "NLOSFW_REQUIRE_BROWSER=1" in script
    assert "libllvm19 chromium chromium-driver" in script
    # only CI's own environment: system packages and y-tal's separate venv
    for line in code:
        words = line.split()
        for tool in ("pytest", "ruff", "mypy", "dev.py"):
            assert tool not in words, f".ci/run runs {tool} itself: {line.strip()}"
        if "pip" in line and "install" in words:
            assert "y-tal" in line, line.strip()
    assert not re.search(r"(plugins|examples)/", "\n".join(code))


# ------------------------------------------------------------------ what dev.py reinstalls
def _wanted(dev, extras=("sweeps",)):
    return {folder: {"name": dev.project_name(path), "hash": dev.fingerprint(path),
                     "extras": list(extras) if folder == "." else []}
            for folder, path in dev.distributions().items()}


def test_a_second_set_up_reinstalls_only_what_changed(dev):
    wanted = _wanted(dev)
    installed = {dev.normalise(w["name"]) for w in wanted.values()}
    stamp = {"torch": "cpu", "dists": wanted}
    assert dev.plan(stamp, wanted, installed) == ([], [])
    assert dev.plan({}, wanted, installed) == (list(wanted), [])            # no record yet
    changed = {**wanted, "plugins/nlosfw-jax": {**wanted["plugins/nlosfw-jax"], "hash": "new"}}
    assert dev.plan(stamp, changed, installed) == (["plugins/nlosfw-jax"], [])
    # the test tools: the core again, with its test extra; a test set-up serves a run
    assert dev.plan(stamp, _wanted(dev, ("sweeps", "test")), installed) == (["."], [])
    tested = {"torch": "cpu", "dists": _wanted(dev, ("sweeps", "test"))}
    assert dev.plan(tested, wanted, installed) == ([], [])
    # uninstalled by hand: installed again; gone from the tree: uninstalled
    assert dev.plan(stamp, wanted, installed - {"nlosfw-torch"}) == (["plugins/nlosfw-torch"],
                                                                     [])
    old = {**stamp, "dists": {**wanted, "plugins/gone": {"name": "nlosfw-gone", "hash": "x",
                                                         "extras": []}}}
    assert dev.plan(old, wanted, installed) == ([], ["nlosfw-gone"])


def test_the_fingerprint_follows_pyproject_and_the_version_file(dev, tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "version.py").write_text('__version__ = "1.0"\n')
    (tmp_path / "pyproject.toml").write_text(
        '[project]\nname = "x"\ndynamic = ["version"]\n[tool.setuptools.dynamic]\n'
        'version = { attr = "pkg.version.__version__" }\n')
    first = dev.fingerprint(tmp_path)
    assert dev.project_name(tmp_path) == "x" and dev.fingerprint(tmp_path) == first
    (tmp_path / "pkg" / "version.py").write_text('__version__ = "1.1"\n')
    assert dev.fingerprint(tmp_path) != first
    (tmp_path / "pkg" / "other.py").write_text("x = 1\n")                # code: no reinstall
    second = dev.fingerprint(tmp_path)
    assert dev.fingerprint(tmp_path) == second


def test_torch_cpu_refuses_a_cuda_resolution_and_the_switch_is_checked(dev):
    report = {"install": [{"metadata": {"name": "torch"}}, {"metadata": {"name": "sympy"}},
                          {"metadata": {"name": "nvidia-cublas-cu12"}},
                          {"metadata": {"name": "triton"}}]}
    assert dev.cuda_packages(report) == ["nvidia-cublas-cu12", "triton"]
    assert dev.cuda_packages({"install": report["install"][:2]}) == []
    assert dev.torch_choice({}) == "cpu" and dev.torch_choice({"TORCH": "CUDA"}) == "cuda"
    with pytest.raises(dev.SetupError, match="TORCH='rocm' is not a torch build; valid: cpu, "):
        dev.torch_choice({"TORCH": "rocm"})


@pytest.mark.parametrize("argv, env, message", [
    (["setup"], {"TORCH": "gpu"}, "dev.py: error: TORCH='gpu' is not a torch build; valid: "
                                  "cpu, cuda (default cpu)\n"),
    (["build"], {}, "usage: python3 dev.py run [OVERRIDE ...] | test [PYTEST_ARG ...] | "
                    "setup [--test]  (TORCH=cpu|cuda, default cpu)\n"),
    (["setup", "--all"], {}, "dev.py: error: setup takes only --test, not --all\n"),
])
def test_bad_input_is_one_line_and_exit_status_2_before_anything_is_done(argv, env, message,
                                                                        tmp_path):
    """Nothing is made or installed: the stamp of the environment is left as it was."""
    stamp = ROOT / ".venv" / "nlosfw-dev.json"
    before = stamp.read_bytes() if stamp.exists() else None
    done = subprocess.run([sys.executable, str(ROOT / "dev.py"), *argv], capture_output=True,
                          text=True, env={**os.environ, **env}, timeout=60, cwd=tmp_path)
    assert (done.returncode, done.stderr, done.stdout) == (2, message, "")
    assert (stamp.read_bytes() if stamp.exists() else None) == before


def test_the_stamp_is_written_whole(dev, tmp_path, monkeypatch):
    monkeypatch.setattr(dev, "STAMP", tmp_path / "stamp.json")
    assert dev.read_stamp() == {}
    dev.write_stamp({"torch": "cpu", "dists": {}})
    assert json.loads((tmp_path / "stamp.json").read_text()) == {"torch": "cpu", "dists": {}}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stamp.json"]
    (tmp_path / "stamp.json").write_text("{half")
    assert dev.read_stamp() == {}

"""CI runs the README's Install and Tests blocks verbatim, and they install what the suite
needs: every distribution of the repository, the linter, the type checker, pytest."""

from __future__ import annotations

import importlib.util
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / ".ci"


def _extractor():
    spec = importlib.util.spec_from_file_location("readme_block", CI / "readme_block.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
    extract = _extractor().readme_block
    assert extract(text, "Install") == "pip install a \\\n  b\n"
    assert extract(text, "Tests") == "pytest\n"
    for missing in ("Run", "Install more"):
        try:
            extract(text, missing)
        except LookupError as err:
            assert "no section" in str(err)
        else:
            raise AssertionError(f"section {missing!r} should be missing")


def test_the_install_block_installs_every_distribution_of_the_repository():
    installs = [c for c in _commands(_block("Install")) if c[:2] == ["pip", "install"]]
    targets = {arg for c in installs for arg in c[2:] if not arg.startswith("-")}
    distributions = {"./" + p.parent.relative_to(ROOT).as_posix()
                     for pattern in ("plugins/*/pyproject.toml", "examples/*/pyproject.toml")
                     for p in ROOT.glob(pattern)}
    assert len(distributions) >= 6
    assert distributions <= targets, distributions - targets
    assert ".[sweeps]" in targets and "torch==2.13.0" in targets
    assert "optional" not in _block("Install")


def test_the_tests_block_lints_type_checks_and_runs_the_whole_suite():
    commands = _commands(_block("Tests"))
    assert commands[:3] == [["pip", "install", ".[test]"], ["ruff", "check", "."], ["mypy"]]
    pytest_command = commands[3]
    assert len(commands) == 4 and pytest_command[0] == "pytest"
    # the whole suite: no paths, no -k/-m selection; only pytest-xdist's process options
    assert all(arg.startswith("-") or arg.isdigit() or arg in ("auto", "loadfile")
               for arg in pytest_command[1:]), pytest_command
    assert not {"-k", "-m", "-x"} & set(pytest_command)


def test_ci_runs_the_readme_blocks_and_no_install_or_test_command_of_its_own():
    script = (CI / "run").read_text()
    code = [line.split("#", 1)[0] for line in script.splitlines()]
    assert "readme Install" in script and "readme Tests" in script
    assert script.index("readme Install") < script.index("readme Tests")
    # only CI's own environment: the venv's pip, y-tal's separate venv, system packages
    for line in code:
        words = line.split()
        for tool in ("pytest", "ruff", "mypy"):
            assert tool not in words, f".ci/run runs {tool} itself: {line.strip()}"
        if "pip" in line and "install" in words:
            assert "--upgrade pip" in line or "y-tal" in line, line.strip()
    assert not re.search(r"(plugins|examples)/", "\n".join(code))

"""Set up nlosfw in ./.venv (first time, or what changed since) and run it, or its tests.

    python3 dev.py run [OVERRIDE ...]    set up, then python -m nlosfw [OVERRIDE ...]
    python3 dev.py test [PYTEST_ARG ...] set up with the test tools, then ruff, mypy, pytest
    python3 dev.py setup [--test]        only set up

Needs only Python >= 3.10 with venv (Debian: python3-venv). The set-up installs torch
first, pinned as plugins/nlosfw-torch asks, in the build ``TORCH`` names: ``cpu`` (the
default; never CUDA: from pytorch.org's CPU index when it answers, else from pip's own
configuration, checked beforehand to hold no CUDA package) or ``cuda`` (pip's default build,
CUDA on Linux x86_64: several GB). Then every distribution of the repository (the core,
plugins/*, examples/*) editable, so a ``git pull`` that changes only code needs no
reinstall. ``.venv/nlosfw-dev.json`` records what was installed; a later call reinstalls
only the distributions whose pyproject.toml (or version file) changed, and nothing when
none did. Errors are one line on stderr, exit status 2 (a failing tool's own status).
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import urllib.error
import urllib.request
from collections.abc import Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / "nlosfw-dev.json"
TORCH_CHOICES = ("cpu", "cuda")
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
#: The extras of the core for each task (the test tools only for ``test``).
CORE_EXTRAS = {"run": ("sweeps",), "test": ("sweeps", "test")}
PYTEST = ("pytest", "-n", "auto", "--maxprocesses", "4", "--dist", "loadfile")
USAGE = ("usage: python3 dev.py run [OVERRIDE ...] | test [PYTEST_ARG ...] | setup [--test]"
         "  (TORCH=cpu|cuda, default cpu)")


class SetupError(Exception):
    """Something the user can fix; reported as one line, exit status 2."""


def say(message: str) -> None:
    sys.stderr.write(f"dev.py: {message}\n")
    sys.stderr.flush()


def distributions(root: Path = ROOT) -> dict[str, Path]:
    """Every distribution of the repository by its folder relative to ``root`` ('.' first)."""
    found = [root / "pyproject.toml", *sorted(root.glob("plugins/*/pyproject.toml")),
             *sorted(root.glob("examples/*/pyproject.toml"))]
    return {p.parent.relative_to(root).as_posix(): p.parent for p in found}


def project_name(folder: Path) -> str:
    """The ``[project] name`` of the pyproject.toml in ``folder``."""
    text = (folder / "pyproject.toml").read_text(encoding="utf-8")
    match = re.search(r"^\[project\][^\[]*?^name\s*=\s*[\"']([^\"']+)[\"']", text,
                      flags=re.MULTILINE | re.DOTALL)
    if match is None:
        raise SetupError(f"{folder / 'pyproject.toml'}: no [project] name")
    return match.group(1)


def fingerprint(folder: Path) -> str:
    """A hash of what an editable install of ``folder`` copies into the environment: its
    pyproject.toml and the module a dynamic version is read from."""
    text = (folder / "pyproject.toml").read_text(encoding="utf-8")
    digest = hashlib.sha256(text.encode())
    for module in re.findall(r"version\s*=\s*\{\s*attr\s*=\s*[\"']([\w.]+)\.\w+[\"']", text):
        base = folder.joinpath(*module.split("."))
        for candidate in (base.with_suffix(".py"), base / "__init__.py"):
            if candidate.is_file():
                digest.update(candidate.read_bytes())
    return digest.hexdigest()


def torch_pin(root: Path = ROOT) -> str:
    """The exact torch requirement of plugins/nlosfw-torch (``torch==X.Y.Z``)."""
    text = (root / "plugins" / "nlosfw-torch" / "pyproject.toml").read_text(encoding="utf-8")
    match = re.search(r"[\"'](torch==[\w.]+)[\"']", text)
    if match is None:
        raise SetupError("plugins/nlosfw-torch/pyproject.toml pins no torch==VERSION")
    return match.group(1)


def torch_choice(environ: Mapping[str, str] = os.environ) -> str:
    """The torch build ``TORCH`` names (default cpu); a one-line error for another value."""
    choice = environ.get("TORCH", "cpu").strip().lower() or "cpu"
    if choice not in TORCH_CHOICES:
        raise SetupError(f"TORCH={environ['TORCH']!r} is not a torch build; valid: "
                         f"{', '.join(TORCH_CHOICES)} (default cpu)")
    return choice


def cuda_packages(report: dict) -> list[str]:
    """The CUDA packages (nvidia-*, triton) a ``pip install --dry-run --report`` would install."""
    names = [item.get("metadata", {}).get("name", "") for item in report.get("install", [])]
    return sorted(n for n in names if n.lower().startswith("nvidia") or n.lower() == "triton")


def plan(stamp: dict, wanted: dict[str, dict], installed: set[str]) -> tuple[list[str], list[str]]:
    """(folders to install, project names to uninstall): the distributions whose fingerprint
    changed, that need more extras, or that are not installed; and those gone from the tree."""
    done = stamp.get("dists", {})
    changed = []
    for folder, want in wanted.items():
        had = done.get(folder)
        if (had is None or had["hash"] != want["hash"] or not set(want["extras"]) <= set(
                had["extras"]) or normalise(want["name"]) not in installed):
            changed.append(folder)
    gone = [had["name"] for folder, had in done.items() if folder not in wanted]
    return changed, gone


def normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def venv_python() -> Path:
    return VENV / "bin" / "python"


def venv_env() -> dict[str, str]:
    """The environment of a command run inside the virtual environment (as if activated)."""
    env = dict(os.environ, VIRTUAL_ENV=str(VENV), PIP_DISABLE_PIP_VERSION_CHECK="1")
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env.pop("PYTHONHOME", None)
    return env


def pip(*args: str) -> None:
    command = [str(venv_python()), "-m", "pip", *args]
    say("$ pip " + " ".join(args))
    if subprocess.run(command, env=venv_env(), check=False).returncode != 0:
        raise SetupError(f"pip {args[0]} failed (its output is above); fix that and run "
                         "dev.py again: what was installed stays")


def venv_state() -> dict | None:
    """The virtual environment's Python version and installed distributions (``None``: no
    working one)."""
    if not venv_python().exists():
        return None
    code = ("import json, sys, importlib.metadata as m; print(json.dumps({'python': "
            "'%d.%d' % sys.version_info[:2], 'dists': {d.metadata['Name']: d.version "
            "for d in m.distributions() if d.metadata['Name']}, 'torch_requires': "
            "[r for d in m.distributions() if d.metadata['Name'] == 'torch' "
            "for r in (d.requires or [])]}))")
    try:
        out = subprocess.run([str(venv_python()), "-c", code], capture_output=True, text=True,
                             env=venv_env(), timeout=120, check=True).stdout
        return json.loads(out)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None


def make_venv(stamp: dict) -> dict:
    """A working ./.venv for this Python (made anew when it was ours and is broken or of
    another Python); its state."""
    python = "{}.{}".format(*sys.version_info[:2])
    state = venv_state()
    if state is not None and state["python"] == python:
        return state
    if VENV.exists():
        if not stamp and any(VENV.iterdir()):
            found = f"Python {state['python']}" if state else "a broken Python"
            raise SetupError(f"{VENV} holds {found}, not {python}, and was not made by dev.py; "
                             "remove it, or run dev.py with the Python it was made with")
        say(f"{VENV} is broken or of another Python: making it anew")
        shutil.rmtree(VENV)
    say(f"making the virtual environment {VENV} (Python {python})")
    made = subprocess.run([sys.executable, "-m", "venv", str(VENV)], capture_output=True,
                          text=True, check=False)
    if made.returncode != 0:
        shutil.rmtree(VENV, ignore_errors=True)
        reason = (made.stderr.strip().splitlines() or ["unknown error"])[-1]
        raise SetupError(f"python3 -m venv failed ({reason}); on Debian or Ubuntu install "
                         "python3-venv: sudo apt-get install -y python3-venv")
    pip("install", "-q", "--upgrade", "pip")
    state = venv_state()
    if state is None:
        raise SetupError(f"{venv_python()} does not run after making {VENV}")
    return state


def reachable(url: str, timeout: float = 5.0) -> bool:
    """Whether ``url``'s server answers within ``timeout`` seconds (any HTTP status)."""
    try:
        with urllib.request.urlopen(urllib.request.Request(url, method="HEAD"), timeout=timeout):
            return True
    except urllib.error.HTTPError:
        return True
    except (OSError, ValueError):
        return False


def install_torch(choice: str, state: dict) -> None:
    """torch as plugins/nlosfw-torch pins it, in the build ``choice`` names (see the module
    docstring); a CPU choice that pip would satisfy with CUDA packages is refused."""
    pin = torch_pin()
    installed_cuda = any(r.lower().startswith("nvidia") for r in state["torch_requires"])
    if "torch" in state["dists"] and installed_cuda != (choice == "cuda"):
        pip("uninstall", "-q", "-y", "torch")   # the other build: same version, so pip keeps it
    if choice == "cuda":
        pip("install", "-q", pin)
        after = venv_state() or {"torch_requires": []}
        if not any(r.lower().startswith("nvidia") for r in after["torch_requires"]):
            say(f"TORCH=cuda, but pip's configuration gave a build of {pin} without CUDA")
        return
    extra = ["--extra-index-url", CPU_INDEX] if reachable(CPU_INDEX + "/torch/") else []
    if not extra:
        say(f"{CPU_INDEX} does not answer: taking torch's CPU build from pip's configuration")
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.json"
        pip("install", "-q", "--dry-run", "--report", str(report), pin, *extra)
        cuda = cuda_packages(json.loads(report.read_text(encoding="utf-8")))
    if cuda:
        raise SetupError(f"TORCH=cpu, but pip would install the CUDA build of {pin} (with "
                         f"{', '.join(cuda[:3])}, ...: several GB) and {CPU_INDEX} does not "
                         "answer; let it answer, add a folder holding a CPU wheel to pip's "
                         "find-links, or set TORCH=cuda to take the CUDA build")
    pip("install", "-q", pin, *extra)


def setup(task: str) -> None:
    """Bring ./.venv up to date for ``task`` ('run' or 'test'); install only what changed."""
    if sys.version_info < (3, 10):  # noqa: UP036 (dev.py itself runs on older ones)
        raise SetupError("nlosfw needs Python >= 3.10; run dev.py with a newer python3")
    choice = torch_choice()
    with open(__file__, encoding="utf-8") as lock:   # one set-up at a time per checkout
        fcntl.flock(lock, fcntl.LOCK_EX)
        stamp = read_stamp()
        state = make_venv(stamp)
        if not STAMP.exists():
            stamp = {}
        wanted = {folder: {"name": project_name(path), "hash": fingerprint(path),
                           "extras": list(CORE_EXTRAS[task]) if folder == "." else []}
                  for folder, path in distributions().items()}
        installed = {normalise(n) for n in state["dists"]}
        if stamp.get("torch") != choice or "torch" not in installed:
            install_torch(choice, state)
            write_stamp({**stamp, "torch": choice})
            stamp = read_stamp()
        changed, gone = plan(stamp, wanted, installed)
        for folder in changed:   # keep extras an earlier task installed
            had = stamp.get("dists", {}).get(folder, {}).get("extras", [])
            wanted[folder]["extras"] = sorted(set(had) | set(wanted[folder]["extras"]))
        if gone:
            pip("uninstall", "-q", "-y", *gone)
        if changed:
            targets = []
            for folder in changed:
                extras = wanted[folder]["extras"]
                targets += ["-e", folder + (f"[{','.join(extras)}]" if extras else "")]
            pip("install", "-q", *targets)
        dists = {f: wanted[f] if f in changed else stamp["dists"][f] for f in wanted}
        write_stamp({"torch": choice, "dists": dists})
        if not changed and not gone:
            say(f"{VENV} is up to date ({len(wanted)} distributions, torch {choice})")


def read_stamp() -> dict:
    try:
        stamp = json.loads(STAMP.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return stamp if isinstance(stamp, dict) else {}


def write_stamp(stamp: dict) -> None:
    partial = STAMP.with_suffix(".tmp")
    partial.write_text(json.dumps(stamp, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    partial.replace(STAMP)


def run_in_venv(command: list[str], last: bool = False) -> int:
    """Run ``command`` inside the virtual environment from the repository root (``last``:
    in place of this process, so signals reach it directly)."""
    say("$ " + " ".join(command))
    program = shutil.which(command[0], path=venv_env()["PATH"]) or command[0]
    if last:
        os.execve(program, command, venv_env())
    return subprocess.run([program, *command[1:]], env=venv_env(), check=False).returncode


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("run", "test", "setup"):
        sys.stderr.write(USAGE + "\n")
        return 2
    task, args = argv[0], argv[1:]
    os.chdir(ROOT)
    try:
        if task == "setup":
            if args not in ([], ["--test"]):
                raise SetupError(f"setup takes only --test, not {' '.join(args)}")
            setup("test" if args else "run")
            return 0
        setup(task)
    except SetupError as err:
        say(f"error: {err}")
        return 2
    if task == "run":
        return run_in_venv(["python", "-m", "nlosfw", *args], last=True)
    for command in (["ruff", "check", "."], ["mypy"]):
        status = run_in_venv(command)
        if status != 0:
            return status
    return run_in_venv([*PYTEST, *args], last=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

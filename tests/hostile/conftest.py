"""Helpers of the hostile suite: the command line as a user runs it, small real file systems,
read-only places, runs to interrupt.

A run to interrupt, or to keep alive while other commands try its directory, is held at a
pause point (:mod:`nlosfw.pipeline.pause`: ``tools.start_held``, ``tools.wait_held``,
``tools.release``), never made slow: the tests wait on files and processes, with generous
timeouts, and never on the clock.

Test modules reach the helpers through the ``tools`` fixture (``tools.nlosfw(...)``,
``tools.QUICK``, ...). Small file systems are real tmpfs mounts: mounted directly when
this process may (root), else inside a user namespace (``unshare -rm``) around the
command under test, whose files are copied out before the namespace ends. Where neither
works the tests that need one skip and say so; ENOSPC injected at the write calls
(``test_faults.py``) covers the same code paths everywhere.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest

from nlosfw.pipeline.pause import ENV as PAUSE_ENV

#: A run of a few seconds: the tiny scene, the interp baseline, the fast imager.
QUICK = ("scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=21", "reconstruction.n_depths=4")


def nlosfw(*args: str, cwd: Path, env: dict[str, str] | None = None,
           prefix: Sequence[str] = ()) -> subprocess.CompletedProcess[str]:
    """``python -m nlosfw ARGS`` in a subprocess (``prefix``: a wrapper command)."""
    full_env = {**os.environ, "COLUMNS": "200", **(env or {})}
    return subprocess.run([*prefix, sys.executable, "-m", "nlosfw", *args], cwd=cwd,
                          env=full_env, capture_output=True, text=True, timeout=900,
                          check=False)


def one_error_line(result: subprocess.CompletedProcess[str]) -> str:
    """The single line the command printed on stderr (no traceback), checked as such."""
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert "Traceback" not in result.stderr, result.stderr
    errors = [line for line in lines if line.startswith(("error:", "interrupted"))]
    assert len(errors) == 1, result.stderr
    return errors[0]


def temporaries(root: Path) -> list[Path]:
    """Temporary files of atomic writes left under ``root``."""
    return [p for p in root.rglob("*") if ".tmp" in p.name]


@pytest.fixture()
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


# ------------------------------------------------------------------- file systems
def _try(cmd: Sequence[str]) -> bool:
    try:
        return subprocess.run(list(cmd), capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@contextlib.contextmanager
def _mounted(point: Path, options: str) -> Iterator[Path]:
    point.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(point)], check=True,
                   capture_output=True)
    try:
        yield point
    finally:
        subprocess.run(["umount", "-l", str(point)], check=False, capture_output=True)


def _mount_mode() -> str | None:
    """``direct`` (this process can mount), ``userns`` (``unshare -rm`` can), else None."""
    probe = Path("/tmp") / f"nlosfw-mount-probe-{uuid.uuid4().hex[:8]}"
    probe.mkdir()
    try:
        if _try(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(probe)]):
            _try(["umount", "-l", str(probe)])
            return "direct"
        if shutil.which("unshare") and _try(
                ["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o size=64k tmpfs {probe}"]):
            return "userns"
        return None
    finally:
        with contextlib.suppress(OSError):
            probe.rmdir()


MOUNT_MODE = _mount_mode()
NO_MOUNT = ("cannot mount a small file system here (not root, no user namespaces): the "
            "ENOSPC-injection tests cover the same write paths")


class SmallDisk:
    """A tmpfs of ``size`` bytes at ``path`` for commands run through :meth:`run`.

    In ``direct`` mode it is mounted for the test's duration; in ``userns`` mode it is
    mounted inside the namespace each command runs in, and its files are copied to
    ``path`` when the command ends (so tests read them from ``path`` either way).
    """

    def __init__(self, path: Path, size: int, mode: str) -> None:
        self.path, self.size, self.mode = path, size, mode

    def run(self, *args: str, cwd: Path,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
        if self.mode == "direct":
            return nlosfw(*args, cwd=cwd, env=env)
        inner = self.path.with_name(self.path.name + ".ns")
        inner.mkdir(exist_ok=True)
        script = (f'mount -t tmpfs -o size={self.size} tmpfs "{inner}" && '
                  f'cp -a "{self.path}"/. "{inner}"/ && "$@"; rc=$?; '
                  f'rm -rf "{self.path}"/* "{self.path}"/.[!.]* 2>/dev/null; '
                  f'cp -a "{inner}"/. "{self.path}"/; exit $rc')
        args = tuple(a.replace(str(self.path), str(inner)) for a in args)
        return nlosfw(*args, cwd=cwd, env=env, prefix=["unshare", "-rm", "sh", "-c", script,
                                                       "sh"])


@pytest.fixture()
def small_disk(tmp_path: Path) -> Iterator[object]:
    """``small_disk(size)``: a :class:`SmallDisk` of ``size`` bytes (skips without mounts)."""
    if MOUNT_MODE is None:
        pytest.skip(NO_MOUNT)
    with contextlib.ExitStack() as stack:
        def make(size: int, name: str = "disk") -> SmallDisk:
            path = tmp_path / name
            path.mkdir()
            if MOUNT_MODE == "direct":
                stack.enter_context(_mounted(path, f"size={size}"))
            return SmallDisk(path, size, MOUNT_MODE or "")

        yield make


@pytest.fixture()
def read_only_dir(tmp_path: Path) -> Iterator[Path]:
    """An empty directory no process of this user can write into: a read-only tmpfs for
    root (whom permissions do not stop), else a directory without write permission."""
    path = tmp_path / "read-only"
    path.mkdir()
    if os.geteuid() != 0:
        path.chmod(0o555)
        try:
            yield path
        finally:
            path.chmod(0o755)
        return
    if MOUNT_MODE != "direct":
        pytest.skip("root cannot be denied writing without mounting a read-only file system, "
                    "and mounting is not possible here")
    with _mounted(path, "ro,size=64k"):
        yield path


@pytest.fixture()
def read_only_cache(tmp_path: Path) -> Iterator[Path]:
    """A cache directory holding one entry, that cannot be written (as :func:`read_only_dir`)."""
    from nlosfw.pipeline.cache import Cache

    path = tmp_path / "ro-cache"

    def fill() -> None:
        Cache(path).get_or_compute("blobs", "0" * 64, lambda: b"x" * 100,
                                   lambda p, v: p.write_bytes(v), lambda p: p.read_bytes())

    if os.geteuid() != 0:
        fill()
        (path / "blobs").chmod(0o555)
        try:
            yield path
        finally:
            (path / "blobs").chmod(0o755)
        return
    if MOUNT_MODE != "direct":
        pytest.skip("root cannot be denied writing without mounting a read-only file system, "
                    "and mounting is not possible here")
    with _mounted(path, "size=1m"):
        fill()
        subprocess.run(["mount", "-o", "remount,ro", str(path)], check=True, capture_output=True)
        yield path


# ----------------------------------------------------------------------- signals
def start_run(*args: str, cwd: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
    """``python -m nlosfw ARGS`` started in the background (its own process group)."""
    full_env = {**os.environ, "COLUMNS": "200", **(env or {})}
    return subprocess.Popen([sys.executable, "-m", "nlosfw", *args], cwd=cwd, env=full_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def start_held(point: str, *args: str, cwd: Path) -> tuple[subprocess.Popen, Path]:
    """``python -m nlosfw ARGS`` started in the background and held at pause point
    ``point`` (:mod:`nlosfw.pipeline.pause`); the run and the pause point's directory."""
    pause = Path(cwd) / f"pause-{uuid.uuid4().hex[:8]}"
    proc = start_run(*args, cwd=cwd, env={PAUSE_ENV: f"{point}:{pause}"})
    return proc, pause


def wait_held(pause: Path, proc: subprocess.Popen, timeout: float = 600.0) -> None:
    """Wait until the run ``proc`` is held at its pause point (``pause/reached`` names it);
    fail saying so when it ends first or ``timeout`` seconds pass."""
    reached = pause / "reached"
    deadline = time.monotonic() + timeout
    while not reached.exists():
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the run (exit status {proc.returncode}) ended before "
                                 f"reaching its pause point {pause}:\n{out}\n{err}")
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            raise AssertionError(f"the run did not reach its pause point ({reached} was not "
                                 f"written) within {timeout:.0f} s:\n{out}\n{err}")
        time.sleep(0.05)
    assert reached.read_text().strip() == str(proc.pid), "another process reached the point"


def release(pause: Path) -> None:
    """Let a run held at the pause point ``pause`` go on."""
    (pause / "release").touch()


def finish(proc: subprocess.Popen, timeout: float = 600.0,
           waited_for: str = "end") -> tuple[int, str, str]:
    """Wait for the run to end; its exit status and output (killed, failing, after
    ``timeout`` seconds, saying what it ``waited_for``)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        raise AssertionError(f"the run did not {waited_for} within {timeout:.0f} s:\n{out}\n"
                             f"{err}") from None
    return proc.returncode, out, err


def stop(proc: subprocess.Popen, sig: int) -> tuple[int, str, str]:
    """Send ``sig`` to the run; its exit status and output."""
    proc.send_signal(sig)
    return finish(proc, 600.0, f"stop after signal {sig}")


class Tools:
    """The helpers above, for test modules (which cannot import this conftest); ``run`` is
    :func:`nlosfw.cli.main` in this process (faster than a subprocess, same code path
    after the interpreter starts)."""

    QUICK = QUICK
    MOUNT_MODE = MOUNT_MODE

    def __init__(self, capsys: pytest.CaptureFixture[str]) -> None:
        self._capsys = capsys

    def run(self, *args: str) -> subprocess.CompletedProcess[str]:
        from nlosfw.cli import main

        self._capsys.readouterr()
        status = main(list(args))
        out = self._capsys.readouterr()
        return subprocess.CompletedProcess(list(args), status, out.out, out.err)

    nlosfw = staticmethod(nlosfw)
    one_error_line = staticmethod(one_error_line)
    temporaries = staticmethod(temporaries)
    start_run = staticmethod(start_run)
    start_held = staticmethod(start_held)
    wait_held = staticmethod(wait_held)
    release = staticmethod(release)
    finish = staticmethod(finish)
    stop = staticmethod(stop)


@pytest.fixture()
def tools(capsys: pytest.CaptureFixture[str]) -> Tools:
    return Tools(capsys)

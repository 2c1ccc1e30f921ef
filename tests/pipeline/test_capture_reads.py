"""A command reads its capture file once: ``python -m nlosfw capture.path=FILE ...`` and
``python -m nlosfw image FILE``, their checks before the run included, open the file (by
any name: here a link to it) at most three times, read it in full once, and build one
plugin host.

Counted in a fresh process by an audit hook (:func:`sys.addaudithook`): Python's ``open``
events naming the file, nlosfw's ``nlosfw.capture.read`` (a full read) and
``nlosfw.plugins.load`` (a plugin host built); and, where strace can trace the command,
every ``openat`` of the file by any library (HDF5's own included)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nlosfw.capture.hdf5 import write_capture
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from tests.real_data import real_capture

#: The most times a command may open its capture file.
MAX_OPENS = 3

_COUNTING = """
import json, os, sys
target = os.stat(sys.argv[1])
key = (target.st_dev, target.st_ino)
counts = {"opens": 0, "reads": 0, "hosts": 0}

def hook(event, args):
    if event == "open":
        name = args[0]
        if isinstance(name, (str, bytes, os.PathLike)):
            try:
                found = os.stat(name)
            except (OSError, ValueError):
                return
            if (found.st_dev, found.st_ino) == key:
                counts["opens"] += 1
    elif event == "nlosfw.capture.read":
        counts["reads"] += 1
    elif event == "nlosfw.plugins.load":
        counts["hosts"] += 1

sys.addaudithook(hook)
from nlosfw.cli.commands import main
status = main(sys.argv[2:])
sys.stderr.write("COUNTS " + json.dumps({**counts, "status": status}) + "\\n")
"""

#: A quick run: few planes, no single-frequency images, no figures.
QUICK = ("figures.enabled=false", "reconstruction.n_depths=4",
         "reconstruction.single_frequency_images=0", "output.keep=[]")


def counted(capture: Path, *args: str, cwd: Path) -> dict[str, int]:
    """Opens of ``capture``, full reads and plugin hosts of ``python -m nlosfw ARGS``."""
    done = subprocess.run([sys.executable, "-c", _COUNTING, str(capture), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900, check=False)
    line = [x for x in done.stderr.splitlines() if x.startswith("COUNTS ")]
    assert line, done.stderr[-3000:]
    counts: dict[str, int] = json.loads(line[-1].split(" ", 1)[1])
    assert counts["status"] == 0, done.stderr[-3000:]
    return counts


def traced_opens(capture: Path, *args: str, cwd: Path) -> int | None:
    """The ``openat`` calls (any library's) that open ``capture`` by any name in
    ``python -m nlosfw ARGS``; None where strace cannot trace it."""
    if shutil.which("strace") is None:
        return None
    log = cwd / "openat.log"
    done = subprocess.run(["strace", "-f", "-e", "trace=openat", "-o", str(log),
                           sys.executable, "-m", "nlosfw", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900, check=False)
    if not log.exists() or "PTRACE" in done.stderr or "Operation not permitted" in done.stderr:
        return None
    assert done.returncode == 0, done.stderr[-3000:]
    names = {str(capture), os.path.realpath(capture)}
    opened = 0
    for line in log.read_text(errors="replace").splitlines():
        if "openat(" not in line or "= -1" in line:
            continue
        quoted = line.split('"')
        if len(quoted) > 1 and os.path.realpath(Path(cwd, quoted[1])) in names | {
                os.path.realpath(n) for n in names}:
            opened += 1
    return opened


def _linked(path: Path, folder: Path) -> Path:
    """A symbolic link to ``path`` (the command opens the file through another name)."""
    link = folder / f"link-{path.name}"
    link.symlink_to(path)
    return link


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict[str, Path]:
    """One capture file per reader family: MATLAB 5 (lct), MATLAB 7.3 (fk: HDF5 under
    MATLAB's header) and nlosfw's HDF5."""
    folder = tmp_path_factory.mktemp("captures")
    lct = AnalyticSimulator().simulate(scene_from_config(layouts.lct_scene(resolution=8,
                                                                           bins=1700)))
    counts = np.round(lct.H / lct.H.max() * 50).astype(np.float32)
    fk = AnalyticSimulator().simulate(scene_from_config(layouts.fk_scene(resolution=8)))
    return {"lct": layouts.write_lct(folder / "scan.mat", lct.replace(H=counts)),
            "fk": layouts.write_fk(folder / "fk", fk)[0],
            "nlosfw": write_capture(folder / "capture.hdf5", fixtures.tiny_capture())}


@pytest.mark.parametrize("kind", ["lct", "fk", "nlosfw"])
def test_a_run_opens_its_capture_file_at_most_three_times_and_reads_it_once(
        captures, kind, tmp_path):
    link = _linked(captures[kind], tmp_path)
    counts = counted(link, f"capture.path={link}", "model=interp", "imager=fft", *QUICK,
                     cwd=tmp_path)
    assert counts["reads"] == 1, counts
    assert counts["hosts"] == 1, counts
    assert counts["opens"] <= MAX_OPENS, counts


def test_the_image_command_reads_its_file_once(captures, tmp_path):
    link = _linked(captures["lct"], tmp_path)
    counts = counted(link, "image", str(link), *QUICK, cwd=tmp_path)
    assert (counts["reads"], counts["hosts"]) == (1, 1), counts
    assert counts["opens"] <= MAX_OPENS, counts


@pytest.mark.parametrize("kind", ["lct", "nlosfw"])
def test_no_library_opens_it_more_often(captures, kind, tmp_path):
    """strace sees HDF5's own opens too, which no audit hook does."""
    link = _linked(captures[kind], tmp_path)
    opened = traced_opens(link, f"capture.path={link}", "model=interp", "imager=fft", *QUICK,
                          "hydra.run.dir=run", cwd=tmp_path)
    if opened is None:
        pytest.skip("strace is not installed or cannot trace here")
    assert 1 <= opened <= MAX_OPENS


@pytest.mark.parametrize("command", ["run", "image"])
def test_the_shared_capture_is_opened_at_most_three_times(command, tmp_path):
    path = real_capture("data_diffuse_s")
    link = _linked(path, tmp_path)
    args = (("image", str(link)) if command == "image"
            else (f"capture.path={link}", "model=interp", "imager=fft"))
    counts = counted(link, *args, "cache.enabled=false", *QUICK, cwd=tmp_path)
    assert (counts["reads"], counts["hosts"]) == (1, 1), counts
    assert counts["opens"] <= MAX_OPENS, counts
    opened = traced_opens(link, *args, "cache.enabled=false", *QUICK, "hydra.run.dir=traced",
                          cwd=tmp_path)
    assert opened is None or opened <= MAX_OPENS

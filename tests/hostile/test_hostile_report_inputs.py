"""``python -m nlosfw report DIR`` over a folder an attacker prepared: it reads only regular
files inside DIR (no link leaving it), no control character reaches any output, an
oversized input is refused in one line and long text is cut in every cell, and a report
folder that cannot be made is one line naming the path."""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

import nlosfw
from nlosfw.common.text import MAX_SHOWN
from nlosfw.report.inputs import MAX_RUN_FILE_BYTES

ESC, BEL, CSI = "\x1b", "\x07", "\x9b"
#: A title change for the terminal that shows the file, then a colour through the C1 CSI.
ESCAPES = f"{ESC}]0;pwned{BEL}{CSI}31m"
SECRET = "TOPSECRET-7d1e"
#: Every file a report writes.
OUTPUTS = ("report.csv", "study.csv", "report.md", "report.html")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """One finished run (the quick run, no capture copy needed by a report)."""
    root = tmp_path_factory.mktemp("finished")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(root / "cache"))
        out = nlosfw.run(["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
                          "transform.n_frequencies=21", "reconstruction.n_depths=4"],
                         output_dir=root / "run")
    (out.dir / "capture.hdf5").unlink(missing_ok=True)
    return out.dir


@pytest.fixture()
def runs(workdir, finished_run) -> Path:
    """``workdir/runs/0``: a copy of the finished run, to plant things in."""
    shutil.copytree(finished_run, workdir / "runs" / "0", symlinks=True)
    return workdir / "runs"


def edit_metrics(run_dir: Path, change) -> None:
    path = run_dir / "metrics.json"
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def nothing_written(runs: Path) -> bool:
    return not [p for p in runs.iterdir() if p.name.startswith("report")]


def holds(root: Path, text: str) -> list[Path]:
    """The files under ``root`` holding ``text`` (as UTF-8 or in base64)."""
    needles = (text.encode(), base64.b64encode(text.encode()))
    return [p for p in root.rglob("*") if p.is_file() and not p.is_symlink()
            and any(n in p.read_bytes() for n in needles)]


# ------------------------------------------------------------------ reads stay in DIR
def test_a_config_yaml_linking_outside_is_not_embedded(workdir, tools, runs):
    outside = workdir / "elsewhere.yaml"
    outside.write_text(f"thesis: {{}}\nsecret: {SECRET}\n")
    (runs / "0" / "config.yaml").unlink()
    (runs / "0" / "config.yaml").symlink_to(outside)
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {runs}/0/config.yaml: a link to {outside}, outside {runs}; it is not read "
        "(only the files inside the folder are)")
    assert nothing_written(runs) and holds(runs, SECRET) == []
    assert SECRET not in result.stdout + result.stderr


@pytest.mark.malformed_metrics
def test_a_metrics_json_linking_to_a_system_file_is_not_opened(workdir, tools, runs):
    (runs / "0" / "metrics.json").unlink()
    (runs / "0" / "metrics.json").symlink_to("/etc/passwd")
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {runs}/0/metrics.json: a link to /etc/passwd, outside {runs}; it is not "
        "read (only the files inside the folder are)")
    assert nothing_written(runs)


@pytest.mark.malformed_metrics
def test_a_valid_metrics_json_outside_is_not_reported(workdir, tools, runs):
    """A link to another run's metrics.json outside DIR is refused though it would parse."""
    outside = workdir / "other" / "metrics.json"
    outside.parent.mkdir()
    shutil.copy(runs / "0" / "metrics.json", outside)
    edit_metrics(outside.parent, lambda d: d["run"].update(scene=SECRET))
    (runs / "0" / "metrics.json").unlink()
    (runs / "0" / "metrics.json").symlink_to(outside)
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert "outside" in tools.one_error_line(result)
    assert nothing_written(runs) and SECRET not in result.stdout


def test_a_hydra_folder_linking_outside_is_not_read(workdir, tools, runs):
    outside = workdir / "planted"
    outside.mkdir()
    (outside / "overrides.yaml").write_text(f"- model=interp\n- +secret={SECRET}\n")
    shutil.rmtree(runs / "0" / ".hydra")
    (runs / "0" / ".hydra").symlink_to(outside)
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {runs}/0/.hydra/overrides.yaml: a link to {outside}/overrides.yaml, outside "
        f"{runs}; it is not read (only the files inside the folder are)")
    assert nothing_written(runs) and holds(runs, SECRET) == []


def test_links_that_stay_inside_the_folder_are_read(workdir, tools, runs):
    shared = runs / "shared.yaml"
    shutil.move(runs / "0" / "config.yaml", shared)
    (runs / "0" / "config.yaml").symlink_to("../shared.yaml")
    result = tools.run("report", str(runs))
    assert result.returncode == 0, result.stderr
    assert "published: {}" in (runs / "report" / "report.html").read_text()


def test_a_run_page_embeds_no_figure_linking_outside(workdir, runs):
    """A run's report.html reads its figures and lists its files only inside its folder."""
    from nlosfw.pipeline.metrics import RunMetrics
    from nlosfw.report.html_report import run_report

    run_dir = runs / "0"
    outside = workdir / "private.png"
    outside.write_bytes(b"\x89PNG\r\n\x1a\n" + SECRET.encode() * 10)
    (run_dir / "figures").mkdir()
    (run_dir / "figures" / "loss.png").symlink_to(outside)
    (run_dir / "figures" / "fields_f1.png").write_bytes(b"\x89PNG\r\n\x1a\ninside")
    os.mkfifo(run_dir / "figures" / "fields_f2.png")
    page = run_report(run_dir, RunMetrics.read(run_dir / "metrics.json"), {})
    assert base64.b64encode(b"\x89PNG\r\n\x1a\ninside").decode() in page
    assert base64.b64encode(outside.read_bytes()).decode() not in page
    assert "loss.png" not in page and "fields_f2.png" not in page


# ------------------------------------------------------------------ terminal escapes
def test_escape_sequences_in_metrics_reach_no_output(workdir, tools, runs):
    edit_metrics(runs / "0", lambda d: d["run"].update(scene=f"tiny{ESCAPES}"))
    result = tools.run("report", str(runs))
    assert result.returncode == 0, result.stderr
    for name in OUTPUTS:
        text = (runs / "report" / name).read_text(encoding="utf-8")
        assert not {ESC, BEL, CSI} & set(text), name
    shown = "tiny\\x1b]0;pwned\\x07\\x9b31m"
    assert shown in (runs / "report" / "report.csv").read_text()
    assert shown in (runs / "report" / "report.html").read_text()
    assert not {ESC, BEL, CSI} & set(result.stdout + result.stderr)


def test_escape_sequences_in_overrides_and_config_reach_no_output(workdir, tools, runs):
    (runs / "0" / ".hydra" / "overrides.yaml").write_text(
        json.dumps(["model=interp", f"+note=a{ESCAPES}"]))
    config = (runs / "0" / "config.yaml").read_text()
    (runs / "0" / "config.yaml").write_text(config + f"note: {json.dumps(ESCAPES)}\n")
    result = tools.run("report", str(runs))
    assert result.returncode == 0, result.stderr
    for name in OUTPUTS:
        text = (runs / "report" / name).read_text(encoding="utf-8")
        assert not {ESC, BEL, CSI} & set(text), name
    assert "+note=a\\x1b]0;pwned\\x07\\x9b31m" in (runs / "report" / "report.csv").read_text()


# ------------------------------------------------------------------ oversized inputs
@pytest.mark.malformed_metrics
def test_an_oversized_metrics_json_is_refused_before_it_is_read(workdir, tools, runs):
    size = MAX_RUN_FILE_BYTES + 1024
    edit_metrics(runs / "0", lambda d: d["run"].update(scene="x" * size))
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    actual = (runs / "0" / "metrics.json").stat().st_size
    assert tools.one_error_line(result) == (
        f"error: {runs}/0/metrics.json: {actual:,} bytes, more than the "
        f"{MAX_RUN_FILE_BYTES:,} a report reads from one file; it is not read")
    assert nothing_written(runs)


def test_an_oversized_overrides_yaml_is_refused(workdir, tools, runs):
    path = runs / "0" / ".hydra" / "overrides.yaml"
    path.write_text("- +a=" + "y" * MAX_RUN_FILE_BYTES + "\n")
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith(f"error: {path}: {path.stat().st_size:,} "
                                                   "bytes, more than the")
    assert nothing_written(runs)


def test_long_text_is_cut_in_every_cell(workdir, tools, runs):
    """A 2 M-character scene name (under the file limit) is shown cut, once per cell."""
    long = 2_000_000
    edit_metrics(runs / "0", lambda d: d["run"].update(scene="s" * long))
    shutil.copytree(runs / "0", runs / "1")
    result = tools.run("report", str(runs))
    assert result.returncode == 0, result.stderr
    suffix = f"… ({long:,} characters)"
    cut = "s" * (MAX_SHOWN - len(suffix)) + suffix
    csv_text = (runs / "report" / "report.csv").read_text(encoding="utf-8")
    assert csv_text.count(cut) == 2 and "s" * MAX_SHOWN not in csv_text
    for name in OUTPUTS:
        assert (runs / "report" / name).stat().st_size < 200_000, name
    assert len(result.stdout) < 200_000


# ------------------------------------------------------------------ report folder in the way
def test_a_dangling_link_where_the_report_goes_is_one_line(workdir, tools, runs):
    (runs / "report").symlink_to(workdir / "nowhere")
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {runs}/report: a link to {workdir}/nowhere, which does not exist; remove "
        "it to write the report there")
    assert (runs / "report").is_symlink() and not (workdir / "nowhere").exists()


def _quiet(*cmd: str) -> bool:
    return subprocess.run(list(cmd), capture_output=True, check=False).returncode == 0


@pytest.fixture()
def unwritable():
    """``unwritable(path)``: the folder ``path`` made impossible to write into for this
    process: read-only for a user; for root, whom permissions do not stop, immutable
    (``chattr +i``) or else mounted read-only over itself (skips when neither is allowed)."""
    undo: list[tuple[str, ...]] = []

    def make(path: Path) -> None:
        if os.geteuid() != 0:
            path.chmod(0o555)
            undo.append(("chmod", "755", str(path)))
        elif _quiet("chattr", "+i", str(path)):
            undo.append(("chattr", "-i", str(path)))
        elif _quiet("mount", "--bind", str(path), str(path)):
            undo.append(("umount", "-l", str(path)))
            if not _quiet("mount", "-o", "remount,ro,bind", str(path)):
                pytest.skip("cannot make a folder read-only here (no remount)")
        else:
            pytest.skip("cannot make a folder unwritable for root here (no chattr, no mount)")

    yield make
    for command in reversed(undo):
        subprocess.run(list(command), capture_output=True, check=False)


def test_a_folder_that_cannot_be_written_is_one_line_exit_2(workdir, tools, runs,
                                                             unwritable):
    unwritable(runs)
    result = tools.run("report", str(runs))
    assert result.returncode == 2
    assert tools.one_error_line(result) in (
        f"error: {runs}: a report cannot be written there ({reason})"
        for reason in ("permission denied", "read-only file system"))
    assert nothing_written(runs)


def test_a_full_disk_is_one_line_exit_1(workdir, runs, small_disk):
    disk = small_disk(96 << 10)
    shutil.copytree(runs / "0", disk.path / "0", symlinks=True)
    result = disk.run("report", str(disk.path), cwd=workdir)
    assert result.returncode == 1, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: {disk.path}/report/"), lines
    assert "no space left on device" in lines[0] or "not enough disk space" in lines[0]
    assert "Traceback" not in result.stderr
    assert not (disk.path / "report").exists()          # no half-written report left


# ------------------------------------------------------------------ the run's own log
def test_escape_sequences_in_a_capture_name_reach_no_run_log(workdir, tools):
    """The command line's run.log and the Python API's both show a file name's control
    characters as text."""
    import h5py

    from nlosfw.capture.hdf5 import write_capture
    from nlosfw.common.text import override_value
    from nlosfw.testing import fixtures

    path = write_capture(workdir / f"c{ESCAPES}.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:     # the reader logs the file's name: "assuming +z"
        del f["sensor_grid_normals"]
    quick = ("model=interp", "imager=fft", "figures.enabled=false",
             "transform.n_frequencies=21", "reconstruction.n_depths=4", "stop_after=capture")
    result = tools.run(f"capture.path={override_value(str(path))}", *quick, "hydra.run.dir=cli")
    assert result.returncode == 0, result.stderr
    nlosfw.run([f"capture.path={override_value(str(path))}", *quick],
               output_dir=workdir / "api")
    for run_dir in (workdir / "cli", workdir / "api"):
        log = (run_dir / "run.log").read_text(encoding="utf-8")
        assert "c\\x1b]0;pwned\\x07\\x9b31m.hdf5" in log, log
        assert not {ESC, BEL, CSI} & set(log)

"""Hostile capture files: data outside the file, declared sizes, values of the
wrong type or out of any sensible range, and paths that are not files. Each is refused in
one line naming the file and the dataset, variable or option; nothing outside the file
is read. The hostile files are written here."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io
import scipy.sparse

from nlosfw.capture.fk import FkFormat, read_tofgrid
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.capture.lct import LctFormat
from nlosfw.capture.preprocess import BinWidth, Preprocessing
from nlosfw.capture.source import CaptureSource, load_file_capture, read_capture_file
from nlosfw.common import hdf5_guard
from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field

#: What a hostile file tries to read: its bytes must never reach a capture.
SECRET = b"root:x:0:0:secret-bytes-of-another-file\n" * 4


@pytest.fixture(scope="module")
def catalogue():
    return load_plugins().capture_formats()


def source(**options):
    return config_from_mapping(CaptureSource, options, "capture")


def secret_file(folder: Path) -> Path:
    path = folder / "passwd"
    path.write_bytes(SECRET)
    return path


def other_file(folder: Path) -> Path:
    path = folder / "other.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.frombuffer(SECRET[:64], dtype=np.uint8).astype(np.float32)
    return path


# ------------------------------------------------------------- data outside the file
def _external_storage(f, name, folder):
    f.create_dataset(name, shape=(len(SECRET),), dtype="u1",
                     external=[(str(secret_file(folder)), 0, len(SECRET))])


def _virtual(f, name, folder):
    layout = h5py.VirtualLayout(shape=(64,), dtype="f4")
    layout[:] = h5py.VirtualSource(str(other_file(folder)), "data", shape=(64,))
    f.create_virtual_dataset(name, layout)


def _external_link(f, name, folder):
    f[name] = h5py.ExternalLink(str(other_file(folder)), "/data")


def _soft_link_through_external(f, name, folder):
    f["elsewhere"] = h5py.ExternalLink(str(other_file(folder)), "/")
    f[name] = h5py.SoftLink("/elsewhere/data")


def _dangling_soft_link(f, name, folder):
    f[name] = h5py.SoftLink("/not/here")


LEAKS = {
    "external storage": (_external_storage, "stores its data in 1 external file(s) outside "
                                            "the capture"),
    "virtual dataset": (_virtual, "is a virtual dataset (it maps data from other files)"),
    "external link": (_external_link, "is an external link to "),
    "soft link leaving the file": (_soft_link_through_external, "an external link to "),
    "dangling soft link": (_dangling_soft_link, "is a soft link to '/not/here', which is not "
                                                "an object of this file"),
}


@pytest.mark.parametrize("kind", sorted(LEAKS))
def test_an_hdf5_capture_reading_outside_itself_is_refused(tmp_path, kind, catalogue):
    make, message = LEAKS[kind]
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        del f["H"]
        make(f, "H", tmp_path)
    for read in (lambda: read_capture(path), lambda: read_capture_file(path, None, catalogue)):
        with pytest.raises(DataError) as caught:
            read()
        text = str(caught.value)
        assert text.startswith(f"{path}: ") and message in text, text
        assert "\n" not in text
        assert "'H'" in text or "'elsewhere'" in text


@pytest.mark.parametrize("kind", sorted(LEAKS))
def test_a_matlab_73_capture_reading_outside_itself_is_refused(tmp_path, kind, catalogue):
    path = layouts.write_mat73(tmp_path / "meas_10min.mat",
                               {"meas": np.ones((4, 4, 16), np.float32)})
    make, message = LEAKS[kind]
    with h5py.File(path, "a") as f:
        del f["meas"]
        make(f, "meas", tmp_path)
    with pytest.raises(DataError) as caught:
        read_capture_file(path, None, catalogue)       # detection, then the refusal
    assert str(caught.value).startswith(f"{path}: ") and message in str(caught.value)
    with pytest.raises(DataError, match="refused|not an object"):
        FkFormat().read(path)                           # the format forced


def test_an_external_storage_capture_on_the_command_line(workdir, tools):
    path = write_capture(workdir / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        del f["scene_info"]
        _external_storage(f, "scene_info", workdir)
    result = tools.run(f"capture.path={path}", *tools.QUICK[1:])
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {path}: dataset 'scene_info' stores its data in 1 external file(s) outside "
        "the capture; refused: copy the data into the capture file")
    assert not (workdir / "outputs").exists() and not (workdir / "cache").exists()


def test_nlosfw_own_files_reading_outside_themselves_are_refused(tmp_path):
    path = write_phasor_field(tmp_path / "f.hdf5", fixtures.point_phasor_field())
    with h5py.File(path, "a") as f:
        _external_link(f, "extra", tmp_path)
    with pytest.raises(DataError, match=r"f\.hdf5: 'extra' is an external link to "):
        read_phasor_field(path)
    os.mkfifo(tmp_path / "fifo.hdf5")
    with pytest.raises(DataError, match=r"fifo\.hdf5: file is a FIFO \(named pipe\)"):
        read_phasor_field(tmp_path / "fifo.hdf5")


def test_a_soft_link_inside_the_file_is_followed(tmp_path):
    capture = fixtures.tiny_capture()
    path = write_capture(tmp_path / "c.hdf5", capture)
    with h5py.File(path, "a") as f:
        f.move("H", "stored_H")
        f["H"] = h5py.SoftLink("/stored_H")
    np.testing.assert_array_equal(read_capture(path).H, capture.H)


# ----------------------------------------------------------------------- sizes
def test_an_undefined_800_gb_dataset_is_never_read(tmp_path, catalogue):
    capture = fixtures.tiny_capture()
    path = write_capture(tmp_path / "c.hdf5", capture)
    with h5py.File(path, "a") as f:      # 800 GB declared, nothing stored
        f.create_dataset("extra", shape=(100_000, 1000, 1000), dtype="f8", chunks=(1, 10, 10))
    assert path.stat().st_size < 1_000_000
    np.testing.assert_array_equal(read_capture(path).H, capture.H)
    loaded = load_file_capture(source(path=str(path)), catalogue)
    np.testing.assert_array_equal(loaded.prepared.capture.H, capture.H)


def test_a_defined_dataset_larger_than_memory_is_refused_before_it_is_read(tmp_path):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:      # 800 GB of sensor points declared
        del f["sensor_grid_xyz"]
        f.create_dataset("sensor_grid_xyz", shape=(100_000, 1000, 1000), dtype="f8",
                         chunks=(1, 10, 10))
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value).startswith(
        f"{path}: dataset 'sensor_grid_xyz' declares 800.0 GB (shape [100000, 1000, 1000] of "
        "float64), more than the ")


def test_the_dataset_limit_is_the_one_named(tmp_path, monkeypatch):
    """A 4 GB-sized refusal shown with a small limit: the size is shape × item size."""
    capture = fixtures.tiny_capture()
    path = write_capture(tmp_path / "c.hdf5", capture)
    monkeypatch.setattr(hdf5_guard, "dataset_limit", lambda: 999)
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value).startswith(f"{path}: dataset '")
    assert "more than the 999 B of memory available; refused before reading it" in \
        str(caught.value)
    monkeypatch.setattr(hdf5_guard, "dataset_limit", lambda: capture.H.nbytes - 1)
    with pytest.raises(DataError, match=r"dataset 'H' declares 65\.5 kB \(shape \[256, 8, 8\] "
                                        r"of float32\)"):
        read_capture(path)
    monkeypatch.setattr(hdf5_guard, "dataset_limit", lambda: capture.H.nbytes)
    read_capture(path)


# ---------------------------------------------------------------- not a file
def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _loop(path: Path) -> Path:
    other = path.with_name("loop-b")
    path.symlink_to(other)
    other.symlink_to(path)
    return path


NOT_FILES = {
    "directory": (lambda p: (p.mkdir(), p)[1], "is a directory, not a file"),
    "fifo": (_fifo, "is a FIFO (named pipe), not a regular file"),
    "device": (lambda p: Path("/dev/zero"), "is a device, not a regular file"),
    "symlink loop": (_loop, "is a symbolic link loop (it never reaches a file)"),
}


@pytest.mark.parametrize("kind", sorted(NOT_FILES))
def test_a_capture_path_that_is_not_a_file_says_what_it_is(workdir, tools, kind):
    make, what = NOT_FILES[kind]
    path = make(workdir / "capture.hdf5")
    result = tools.run(f"capture.path={path}", "model=interp")
    assert result.returncode == 2
    assert tools.one_error_line(result) == f"error: capture.path: {path} {what}"
    assert not (workdir / "outputs").exists()


@pytest.mark.parametrize("kind", ["fifo", "directory"])
def test_a_tofgrid_that_is_not_a_file_says_what_it_is(tmp_path, kind):
    make, what = NOT_FILES[kind]
    path = make(tmp_path / "tof.mat")
    with pytest.raises(ConfigError) as caught:
        load_file_capture(source(path=str(fk_file(tmp_path)), tofgrid=str(path)),
                          load_plugins().capture_formats())
    assert str(caught.value) == f"capture.tofgrid: {path} {what}"


def test_a_relative_capture_path_with_hydra_chdir_is_refused(workdir, tools):
    write_capture(workdir / "c.hdf5", fixtures.tiny_capture())
    result = tools.run("hydra.job.chdir=true", "capture.path=c.hdf5", "model=interp")
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        "error: capture.path: 'c.hdf5' is a relative path, but hydra.job.chdir=true runs in "
        "the run directory, where it names another file; give an absolute path")
    assert not (workdir / "outputs").exists()


# ------------------------------------------------------------- values of a capture
def fk_file(folder: Path, n: int = 4, bins: int = 64) -> Path:
    rng = np.random.default_rng(0)
    return layouts.write_mat73(folder / "meas_10min.mat",
                               {"meas": rng.random((n, n, bins)).astype(np.float32)})


def mat5_variable(path: Path, name: str, value: object) -> Path:
    scipy.io.savemat(str(path), {name: value}, format="5")
    return path


TOFGRIDS = {
    "string": ("12 34; 56 78", "must be numeric, got MATLAB class char"),
    "cell array": (np.array([[1.0, "a"], [2.0, 3.0]], dtype=object),
                   "must be numeric, got MATLAB class cell"),
    "sparse matrix": (scipy.sparse.csc_matrix(np.eye(4)), "must be numeric, got MATLAB class "
                                                          "sparse"),
    "complex": (np.full((4, 4), 1 + 2j), "must be real, got complex numbers"),
    "negative": (np.full((4, 4), -100.0), "holds delays from -100 to -100 ps; expected times "
                                          "of flight from 0 to 1e+06 ps"),
    "absurd": (np.full((4, 4), 1e30), "holds delays from 1e+30 to 1e+30 ps"),
    "NaN": (np.full((4, 4), np.nan), "contains NaN or inf"),
}


@pytest.mark.parametrize("kind", sorted(TOFGRIDS))
def test_a_hostile_tofgrid_is_refused_naming_the_variable(tmp_path, kind):
    value, message = TOFGRIDS[kind]
    path = mat5_variable(tmp_path / "tof.mat", "tofgrid", value)
    with pytest.raises(DataError) as caught:
        read_tofgrid(path)
    assert str(caught.value).startswith(f"{path}: variable 'tofgrid' ")
    assert message in str(caught.value)
    with pytest.raises(ConfigError) as caught:        # as the run's option
        load_file_capture(source(path=str(fk_file(tmp_path)), tofgrid=str(path)),
                          load_plugins().capture_formats())
    assert str(caught.value).startswith(f"capture.tofgrid: {path}: variable 'tofgrid' ")


def test_a_tofgrid_beyond_the_capture_is_refused(tmp_path, catalogue):
    meas = fk_file(tmp_path, bins=64)                 # 64 bins of 32 ps: 2048 ps
    tof = mat5_variable(tmp_path / "tof.mat", "tofgrid", np.full((4, 4), 5000.0))
    with pytest.raises(ConfigError) as caught:
        load_file_capture(source(path=str(meas), tofgrid=str(tof)), catalogue)
    assert str(caught.value) == (f"capture.tofgrid: {tof}: variable 'tofgrid' holds delays up "
                                 "to 5000 ps, beyond the capture's 64 bins of 32 ps")


def test_a_matlab_73_string_tofgrid_is_refused(tmp_path):
    path = layouts.write_mat73(tmp_path / "tof.mat", {"tofgrid": np.zeros((4, 4))})
    with h5py.File(path, "a") as f:                  # MATLAB stores char arrays as uint16
        f["tofgrid"].attrs["MATLAB_class"] = np.bytes_(b"char")
    with pytest.raises(DataError, match=r"variable 'tofgrid' must be numeric, got MATLAB "
                                        r"class char"):
        read_tofgrid(path)


def test_string_meas_is_not_called_corrupt(tmp_path, catalogue):
    path = tmp_path / "meas_10min.mat"
    layouts.write_mat73(path, {"meas": np.zeros((4, 4, 16), np.float32)})
    with h5py.File(path, "a") as f:
        del f["meas"]
        f.create_dataset("meas", data=np.full((16, 4, 4), "ab", dtype=h5py.string_dtype()))
        f["meas"].attrs["MATLAB_class"] = np.bytes_(b"char")
    with pytest.raises(DataError) as caught:
        read_capture_file(path, None, catalogue)
    assert str(caught.value).startswith(f"{path}: variable 'meas' must be numeric, got MATLAB "
                                        "class char")


def test_string_h_in_an_hdf5_capture_is_not_called_corrupt(tmp_path):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        del f["H"]
        f.create_dataset("H", data=np.full((4, 8, 8), "x", dtype=h5py.string_dtype()))
    with pytest.raises(DataError, match=r"c\.hdf5: field 'H' must be numeric, got object"):
        read_capture(path)


@pytest.mark.parametrize("version", [5, 73])
def test_a_truncated_mat_file_is_called_truncated(tmp_path, catalogue, version):
    path = tmp_path / "data.mat"
    rng = np.random.default_rng(1)
    variables = {"rect_data": rng.integers(0, 100, (8, 8, 512)).astype(np.uint16),
                 "width": np.array([[0.5]])}
    if version == 5:
        layouts.write_mat5(path, variables)
    else:
        layouts.write_mat73(path, variables)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError) as caught:
        read_capture_file(path, None, catalogue)
    assert str(caught.value).startswith(f"{path}: ")
    assert "truncated or corrupt" in str(caught.value)
    assert "not a capture file" not in str(caught.value)


# ------------------------------------------------------ numbers out of any range
def lct_file(path: Path, width: float = 0.5, n: int = 4) -> Path:
    rng = np.random.default_rng(2)
    return layouts.write_mat5(path, {"rect_data": rng.integers(1, 50, (n, n, 64)).astype(
        np.uint16), "width": np.array([[width]])})


@pytest.mark.parametrize("width", [1e-300, 1e308])
def test_lct_width_out_of_range_is_blamed_on_width(tmp_path, width):
    path = lct_file(tmp_path / "scene.mat", width=width)
    with pytest.raises(DataError) as caught:
        LctFormat().read(path)
    assert str(caught.value) == (f"{path}: variable 'width' is {width:g}; expected half the "
                                 "side of the scanned square, 0.001 to 1000 metres")


def test_a_one_by_one_scan_is_refused_naming_the_variable(tmp_path):
    path = lct_file(tmp_path / "scene.mat", n=1)
    with pytest.raises(DataError) as caught:
        LctFormat().read(path)
    assert str(caught.value) == (f"{path}: variable 'rect_data': the scan has shape [1, 1, 64]; "
                                 "at least 2 x 2 points of 2 bins are needed to image anything")


@pytest.mark.parametrize(("option", "value"), [("stride", 4), ("stride", 9), ("bin", 4)])
def test_a_stride_or_bin_leaving_one_point_is_refused(tmp_path, catalogue, option, value):
    path = lct_file(tmp_path / "scene.mat", n=4)
    with pytest.raises(ConfigError) as caught:
        load_file_capture(source(path=str(path), gate={"bins": 0}, **{option: value}),
                          catalogue)
    assert str(caught.value) == (f"capture.{option}: {value} leaves fewer than 2 x 2 points of "
                                 "the 4x4 scan grid; valid: 1 to 3")


def test_a_background_equal_to_the_capture_is_refused(tmp_path, catalogue):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with pytest.raises(ConfigError) as caught:       # the same file
        load_file_capture(source(path=str(path), background=str(path)), catalogue)
    assert str(caught.value) == (f"capture.background: {path} is the capture file itself; give "
                                 "the background measurement")
    copy = Path(shutil.copy(path, tmp_path / "bg.hdf5"))   # a copy of it
    with pytest.raises(ConfigError) as caught:
        load_file_capture(source(path=str(path), background=str(copy)), catalogue)
    assert str(caught.value) == ("capture.background: subtracting it leaves nothing: it equals "
                                 "the capture (give the background measurement)")


@pytest.mark.parametrize("delta_t", [1e-300, 1e300])
def test_a_capture_with_an_absurd_bin_width_is_refused(tmp_path, delta_t):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        f["delta_t"][()] = delta_t
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value) == (f"{path}: delta_t: must be a bin width between 1e-07 and 1000 "
                                 f"metres of optical path, got {delta_t:g}")


def test_an_absurd_bin_width_option_is_refused(workdir, tools):
    with pytest.raises(ConfigError, match="gives a bin width of 2.99792e-304 m"):
        BinWidth(ps=1e-300)
    Preprocessing(bin_width=BinWidth(ps=32))
    result = tools.run("capture.bin_width.ps=1e-300", *tools.QUICK)
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert line.startswith("error: capture.bin_width.ps: gives a bin width of 2.99792e-304 m; "
                           "valid: 1e-07 to 1000 m"), line


# ----------------------------------------------------------------- scene_info
YAML_TYPES = ("date: 2024-01-02\nstamp: 2024-01-02 10:30:00\nblob: !!binary aGVsbG8=\n"
              "tags: !!set {b, a}\n2024-05-06: keyed by a date\n")


def test_scene_info_of_yaml_only_types_becomes_json(tmp_path):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        del f["scene_info"]
        f.create_dataset("scene_info", data=YAML_TYPES, dtype=h5py.string_dtype("utf-8"))
    info = read_capture(path).scene_info
    assert json.loads(json.dumps(info)) == {
        "date": "2024-01-02", "stamp": "2024-01-02T10:30:00", "blob": "aGVsbG8=",
        "tags": ["a", "b"], "2024-05-06": "keyed by a date"}


def test_a_run_of_a_capture_with_yaml_dates_writes_its_metrics(workdir, tools):
    path = write_capture(workdir / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        del f["scene_info"]
        f.create_dataset("scene_info", data=YAML_TYPES, dtype=h5py.string_dtype("utf-8"))
    result = tools.run(f"capture.path={path}", *tools.QUICK[1:], "hydra.run.dir=out")
    assert result.returncode == 0, result.stderr
    metrics = json.loads((workdir / "out" / "metrics.json").read_text())
    assert metrics["status"] == "completed"

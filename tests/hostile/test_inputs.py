"""Hostile inputs: alias bombs and code in metadata, huge sizes, malformed ground truth,
non-finite geometry. Each ends with one line before any output exists."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import h5py
import numpy as np
import pytest

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import yaml_safe
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.pipeline.budget import check_memory
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field
from tests.planned import TINY, planned


def capture_file(path: Path, scene_info: str | None = None, **fields: object) -> Path:
    """The tiny capture written to ``path``, then edited: ``scene_info`` replaced by raw
    YAML text, other top-level datasets by ``fields``."""
    write_capture(path, fixtures.tiny_capture())
    with h5py.File(path, "a") as f:
        edits = dict(fields)
        if scene_info is not None:
            edits["scene_info"] = scene_info
        for key, value in edits.items():
            del f[key]
            if key == "scene_info":
                f.create_dataset(key, data=value, dtype=h5py.string_dtype("utf-8"))
            else:
                f.create_dataset(key, data=np.asarray(value))
    return path


def no_output(workdir: Path) -> bool:
    return not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


# ----------------------------------------------------------------------- metadata YAML
#: Nine levels of nine aliases: 9^10 (3.5e9) values once expanded, 400 bytes of text.
BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(9))


@pytest.mark.parametrize(("text", "problem"), [
    (BOMB, "its aliases expand to more than 5,000,000 values (an alias bomb?)"),
    ("a: &a [1, *a]\n", "an alias refers to a node that contains it (a recursive structure)"),
    ("a: " + "[" * 150 + "]" * 150 + "\n", "nested more than 100 levels deep"),
    ("{a: &a {b: [x], c: *a}}", "an alias refers to a node that contains it (a recursive "
                                "structure)"),
])
def test_metadata_yaml_is_bounded(tmp_path, text, problem):
    """Refused from the node graph, before anything is expanded: reading the file takes
    no more memory than a small capture does (the bomb expanded is 3.5e9 values)."""
    path = capture_file(tmp_path / "c.hdf5", scene_info=text)
    tracemalloc.start()
    try:
        with pytest.raises(DataError) as caught:
            read_capture(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert str(caught.value) == f"{path}: field 'scene_info' is refused: {problem}"
    assert peak < 16e6, f"reading the refused metadata peaked at {peak / 1e6:.1f} MB"


def test_an_alias_bomb_is_refused_on_the_command_line(workdir, tools):
    path = capture_file(workdir / "bomb.hdf5", scene_info=BOMB)
    result = tools.run(f"capture.path={path}", *tools.QUICK[1:])
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {path}: field 'scene_info' is refused: its aliases expand to more than "
        "5,000,000 values (an alias bomb?)")
    assert no_output(workdir)


def test_fine_aliases_and_large_plain_metadata_still_load():
    assert yaml_safe.load("a: &x {b: 1}\nc: *x\n") == {"a": {"b": 1}, "c": {"b": 1}}
    depth = np.zeros((200, 200)).tolist()            # a 200 x 200 ground-truth map
    assert yaml_safe.load(yaml_safe.dump({"depth": depth}))["depth"] == depth


def test_metadata_cannot_run_code(tmp_path):
    target = tmp_path / "pwned"
    text = f"x: !!python/object/apply:os.system ['touch {target}']\n"
    path = capture_file(tmp_path / "c.hdf5", scene_info=text)
    with pytest.raises(DataError, match="field 'scene_info' is not valid YAML"):
        read_capture(path)
    assert not target.exists()


# -------------------------------------------------------------------------- huge sizes
@pytest.mark.parametrize(("overrides", "what"), [
    # automatic depths at this wall spacing reach the cap of 512 planes, each 10^10 voxels
    (["scene.wall.resolution=[100000,100000]"],
     "the voxels and images (512 depth planes × 10000000000 voxels each"),
    (["scene.time.bins=10000000000"],
     "the transient H (scene.wall.resolution [16, 16] × scene.time.bins 10000000000"),
    (["transform.n_frequencies=1000000000"],
     "the fields imaged (1000000000 frequencies × 256 samples × 3 fields"),
    (["reconstruction.n_depths=10000000000"],
     "the voxels and images (10000000000 depth planes × 256 voxels each"),
    (["model=siren_torch", "model.steps=10000000000000", "model.eval_every=1"],
     "the training history (model (siren_torch): 10000000000000 steps / eval_every 1"),
])
def test_huge_sizes_are_refused_with_the_estimate(workdir, tools, overrides, what):
    result = tools.run("scene=tiny", "model=interp", *overrides)
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert line.startswith("error: this run needs about "), line
    assert f", most of it for {what}" in line
    assert line.endswith(" are available; make it smaller, or set limits.allow_large=true "
                         "to run anyway")
    assert no_output(workdir) and not (workdir / "cache").exists()   # refused up front


def test_a_capture_file_declaring_a_huge_transient_is_refused_before_it_is_read(workdir,
                                                                               tools):
    path = workdir / "huge.hdf5"
    write_capture(path, fixtures.tiny_capture())
    with h5py.File(path, "a") as f:   # 4 TB declared, nothing stored: a tiny file
        del f["H"]
        f.create_dataset("H", shape=(1_000_000, 1000, 1000), dtype="f4", chunks=(1, 10, 10))
    assert path.stat().st_size < 1_000_000
    result = tools.run(f"capture.path={path}", "model=interp")
    assert result.returncode == 2
    assert "most of it for the transient H (capture.path's transient of 1000000 time bins " \
           "× 1000000 samples" in tools.one_error_line(result)


def test_a_matlab_capture_declaring_a_huge_transient_is_refused_before_it_is_read(workdir,
                                                                                 tools):
    """The estimate sizes every format from its header: an f-k .mat (MATLAB 7.3) file whose
    meas [N, N, T] declares 1000 x 1000 x 100000 bins."""
    path = layouts.write_mat73(workdir / "huge.mat", {"meas": np.zeros((4, 4, 8), np.float32)})
    with h5py.File(path, "a") as f:   # 400 GB declared, nothing stored
        attrs = dict(f["meas"].attrs)
        del f["meas"]
        f.create_dataset("meas", shape=(100_000, 1000, 1000), dtype="f4", chunks=(1, 10, 10))
        f["meas"].attrs.update(attrs)
    assert path.stat().st_size < 1_000_000
    result = tools.run(f"capture.path={path}", "model=interp")
    assert result.returncode == 2
    assert "most of it for the transient H (capture.path's transient of 100000 time bins × " \
           "1000000 samples" in tools.one_error_line(result)
    assert no_output(workdir)


def test_the_estimate_bounds_a_real_run_and_allow_large_overrides_it():
    estimate = planned(TINY).memory
    parts = {p.what: p.nbytes for p in estimate.parts}
    capture = fixtures.tiny_capture(resolution=16, bins=512)
    assert capture.H.nbytes * 4 == parts["the transient H"]   # float64 + float32 + HDF5 image
    with pytest.raises(ConfigError, match=r"this run needs about .* but 1\.0 kB are "
                                          r"available"):
        check_memory(estimate, available=1000)
    check_memory(estimate, allow_large=True, available=1000)
    check_memory(estimate, available=int(estimate.total) + 1)


# ------------------------------------------------------------- ground truth, geometry
@pytest.mark.parametrize(("scene_info", "message"), [
    ("ground_truth: [1, 2]", "scene_info.ground_truth: must be a mapping with depth (and "
                             "albedo) maps, got list"),
    ("ground_truth: {depth: abc}", "scene_info.ground_truth.depth: must hold numbers only"),
    ("ground_truth: {depth: [[1, 2], [3]]}", "scene_info.ground_truth.depth: must hold numbers "
                                            "only (a regular array)"),
    ("ground_truth: {depth: [1, 2, 3]}", "scene_info.ground_truth.depth: must be a non-empty "
                                        "2-D map (X, Y), got shape (3,)"),
    ("ground_truth: {depth: [[.nan, 1]]}", "scene_info.ground_truth.depth: contains NaN or inf"),
    ("ground_truth: {depth: [[1, 2]], albedo: [[1], [2]]}",
     "scene_info.ground_truth.albedo: shape (2, 1) does not match the depth map's (1, 2)"),
    ("volume: {center: [0, 1]}", "scene_info.volume.center: must have 3 numbers, got 2"),
    ("volume: 7", "scene_info.volume: must be a mapping (center, size, rotation), got int"),
])
def test_malformed_ground_truth_is_refused_when_the_capture_is_read(tmp_path, scene_info,
                                                                    message):
    path = capture_file(tmp_path / "c.hdf5", scene_info=scene_info)
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value).startswith(f"{path}: {message}")


@pytest.mark.parametrize(("fields", "message"), [
    ({"laser_xyz": [np.inf, 0.0, 0.25]}, "laser_xyz: must be finite, got [inf, 0.0, 0.25]"),
    ({"sensor_xyz": [np.nan, 0.0, 0.25]}, "sensor_xyz: must be finite, got [nan, 0.0, 0.25]"),
    ({"sensor_grid_normals": np.zeros((8, 8, 3))},
     "sensor_grid_normals: 64 of them have zero length; every normal needs a direction"),
    ({"laser_grid_normals": np.full((1, 1, 3), np.nan)},
     "laser_grid_normals: contains NaN or inf"),
    ({"sensor_grid_xyz": np.full((8, 8, 3), np.inf)}, "sensor_grid_xyz: contains NaN or inf"),
])
def test_non_finite_geometry_is_refused_when_read(tmp_path, fields, message):
    path = capture_file(tmp_path / "c.hdf5", **fields)
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value) == f"{path}: {message}"


def test_non_finite_geometry_in_a_phasor_field_file(tmp_path):
    path = write_phasor_field(tmp_path / "f.hdf5", fixtures.point_phasor_field())
    with h5py.File(path, "a") as f:
        del f["geometry"]
        f.create_dataset("geometry", data="{kind: single_spot, laser_point: [0, .inf, 0]}",
                         dtype=h5py.string_dtype("utf-8"))
    with pytest.raises(DataError, match=r"f\.hdf5: capture geometry: invalid value "
                                        r"\(laser_point: must be 3 finite numbers"):
        read_phasor_field(path)
    with pytest.raises(DataError, match="sensor_xyz: must be 3 finite numbers"):
        CaptureGeometry(kind=fixtures.tiny_capture().kind, sensor_xyz=np.array([0, 0, np.nan]))


@pytest.mark.parametrize(("override", "message"), [
    ("scene.capture.laser_position=[inf,0,0.25]",
     "error: scene.capture.laser_position: must be finite, got (inf, 0.0, 0.25)"),
    ("scene.capture.sensor_position=[0,-inf,0.25]",
     "error: scene.capture.sensor_position: must be finite, got (0.0, -inf, 0.25)"),
    ("scene.geometry.0.position=[0,0,inf]",
     "error: scene.geometry[0].position: must be finite, got (0.0, 0.0, inf)"),
    ("scene.wall.size=[inf,1]", "error: scene.wall.size: must be finite, got (inf, 1.0)"),
    ("scene.time.bin_width=inf", "error: scene.time.bin_width: must be finite, got inf"),
    ("scene.capture.laser_position=[nan,0,0.25]",
     "error: scene.capture.laser_position[0]: must be a number, got NaN"),
])
def test_non_finite_geometry_is_refused_when_configured(workdir, tools, override, message):
    result = tools.run("scene=tiny", "model=interp", override)
    assert result.returncode == 2
    assert tools.one_error_line(result) == message
    assert no_output(workdir)


def test_a_capture_with_bad_geometry_is_refused_on_the_command_line(workdir, tools):
    path = capture_file(workdir / "c.hdf5", sensor_grid_normals=np.zeros((8, 8, 3)))
    result = tools.run(f"capture.path={path}", "model=interp")
    assert result.returncode == 2
    assert tools.one_error_line(result) == (
        f"error: {path}: sensor_grid_normals: 64 of them have zero length; every normal needs "
        "a direction")
    assert no_output(workdir)

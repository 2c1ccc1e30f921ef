"""HDF5 I/O: y-tal interoperability both ways, round trips, clear errors, no clobbering."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from nlosfw import CaptureKind, DataError, HFormat, Reconstruction
from nlosfw.capture.data import YTAL_FIELDS
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common.files import atomic_path
from nlosfw.image.reconstruction_io import read_reconstruction, write_reconstruction
from nlosfw.testing import fixtures
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field

DATA = Path(__file__).resolve().parents[1] / "data"
EXPECTED = np.load(DATA / "ytal_expected.npz")


@pytest.mark.parametrize("name", ["ytal_single", "ytal_confocal", "znlos_confocal"])
def test_reads_files_written_by_ytal_with_ytals_arrays(name):
    cap = read_capture(DATA / f"{name}.hdf5")
    np.testing.assert_array_equal(cap.H, EXPECTED[f"{name}.H"])
    np.testing.assert_allclose(cap.sensor_grid_xyz, EXPECTED[f"{name}.sensor_grid_xyz"])
    np.testing.assert_allclose(cap.laser_grid_xyz, EXPECTED[f"{name}.laser_grid_xyz"])
    assert cap.delta_t == pytest.approx(float(EXPECTED[f"{name}.delta_t"]))
    assert int(cap.H_format) == int(EXPECTED[f"{name}.H_format"])
    assert cap.is_confocal == bool(EXPECTED[f"{name}.is_confocal"])


def test_ytal_metadata_and_none_fields():
    single = read_capture(DATA / "ytal_single.hdf5")
    assert single.kind is CaptureKind.SINGLE_SPOT
    assert single.t_start == pytest.approx(1.5)
    assert single.t_accounts_first_and_last_bounces
    np.testing.assert_allclose(single.laser_xyz, [-0.4, 0.1, 0.3])
    # y-tal stored a numpy array in scene_info as numpy-tagged YAML
    np.testing.assert_array_equal(single.scene_info["volume"]["center"], [0.0, 0.0, 1.0])
    assert single.scene_info["note"] is None
    confocal = read_capture(DATA / "ytal_confocal.hdf5")
    assert confocal.t_start == 0.0  # stored as None (empty dataset) by y-tal
    znlos = read_capture(DATA / "znlos_confocal.hdf5")
    assert znlos.scene_info["original_format"] == "HDF5_ZNLOS"
    assert znlos.scene_info["volume"]["size"] == [0.6, 0.6, 0.6]


def test_round_trip_preserves_every_field(tmp_path):
    cap = fixtures.tiny_capture(device_legs=True)
    path = write_capture(tmp_path / "c.hdf5", cap, compression=4)
    again = read_capture(path)
    for key in YTAL_FIELDS:
        a, b = getattr(cap, key), getattr(again, key)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b, err_msg=key)
        elif key == "scene_info":
            assert json.dumps(a, sort_keys=True, default=str) == json.dumps(
                b, sort_keys=True, default=str)
        else:
            assert a == b, key


def test_file_has_exactly_ytals_layout(tmp_path):
    path = write_capture(tmp_path / "c.hdf5", fixtures.tiny_capture())
    with h5py.File(path) as f:
        assert set(f.keys()) == set(YTAL_FIELDS)
        assert f["H_format"].shape == (1,)
        assert h5py.check_enum_dtype(f["H_format"].dtype)["T_Sx_Sy"] == 1
        assert h5py.check_enum_dtype(f["sensor_grid_format"].dtype) == {
            "UNKNOWN": 0, "N_3": 1, "X_Y_3": 2}
        assert f["delta_t"].shape == () and f["t_accounts_first_and_last_bounces"].dtype == bool
        assert isinstance(f["scene_info"][()], bytes)


YTAL_READER = """
import json, sys, numpy as np, tal
r = tal.io.read_capture(sys.argv[1])
print(json.dumps({"H_sum": float(np.asarray(r.H, dtype=np.float64).sum()),
                  "H_shape": list(r.H.shape), "H_format": r.H_format.name,
                  "confocal": bool(r.is_confocal()), "delta_t": float(r.delta_t),
                  "t_start": float(r.t_start), "legs": bool(r.t_accounts_first_and_last_bounces),
                  "grid0": np.asarray(r.sensor_grid_xyz)[0, 0].tolist(),
                  "laser_xyz": np.asarray(r.laser_xyz).tolist(),
                  "scene_name": r.scene_info["scene"]["name"]}))
"""


@pytest.mark.skipif(not os.environ.get("NLOSFW_YTAL_PYTHON"),
                    reason="set NLOSFW_YTAL_PYTHON to a Python with y-tal installed (CI does)")
@pytest.mark.parametrize("confocal", [False, True])
def test_ytal_opens_files_written_by_nlosfw(tmp_path, confocal):
    cap = fixtures.tiny_capture(confocal=confocal, device_legs=True)
    path = write_capture(tmp_path / "c.hdf5", cap, compression=2)
    out = subprocess.run([os.environ["NLOSFW_YTAL_PYTHON"], "-c", YTAL_READER, str(path)],
                         capture_output=True, text=True, check=True, timeout=300)
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["H_sum"] == pytest.approx(float(cap.H.sum(dtype=np.float64)), rel=1e-6)
    assert seen["H_shape"] == list(cap.H.shape)
    assert seen["H_format"] == "T_Sx_Sy" and seen["confocal"] is confocal
    assert seen["delta_t"] == cap.delta_t and seen["t_start"] == cap.t_start
    assert seen["legs"] is True
    np.testing.assert_allclose(seen["grid0"], cap.sensor_grid_xyz[0, 0])
    np.testing.assert_allclose(seen["laser_xyz"], cap.laser_xyz)
    assert seen["scene_name"] == "tiny"


# --------------------------------------------------------------------------- bad files
def _copy(tmp_path, name="ytal_single.hdf5"):
    target = tmp_path / name
    shutil.copy(DATA / name, target)
    return target


def test_truncated_file(tmp_path):
    path = _copy(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"ytal_single.hdf5: (not a readable HDF5 capture|field)"):
        read_capture(path)


def test_not_hdf5(tmp_path):
    path = tmp_path / "notes.hdf5"
    path.write_text("hello")
    with pytest.raises(DataError, match="notes.hdf5: not a readable HDF5 capture"):
        read_capture(path)


def test_missing_field(tmp_path):
    path = _copy(tmp_path)
    with h5py.File(path, "a") as f:
        del f["delta_t"]
    with pytest.raises(DataError, match="missing field 'delta_t'"):
        read_capture(path)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("delta_t", 0.0, "delta_t: must be a positive number of metres, got 0.0"),
        ("delta_t", -0.01, "delta_t: must be a positive number of metres"),
        ("H", "nan", "H: contains 1 NaN or inf values"),
        ("sensor_grid_xyz", "shape", "dataset 'sensor_grid_xyz' declares shape [5, 4, 3]; "
                                     "expected 24 points of 3 coordinates, as many as H's "
                                     "sensor axes [6, 4]; refused before reading it"),
    ],
)
def test_invalid_fields_name_file_and_field(tmp_path, field, value, message):
    path = _copy(tmp_path)
    with h5py.File(path, "a") as f:
        if value == "nan":
            H = f["H"][()]
            H[3, 1, 1] = np.nan
            del f["H"]
            f["H"] = H
        elif value == "shape":
            grid = f["sensor_grid_xyz"][()][:5]
            del f["sensor_grid_xyz"]
            f["sensor_grid_xyz"] = grid
        else:
            del f[field]
            f[field] = value
    with pytest.raises(DataError) as info:
        read_capture(path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_missing_file():
    with pytest.raises(DataError, match="nope.hdf5: capture file not found"):
        read_capture("nope.hdf5")


# --------------------------------------------------------------------------- safety
def test_never_overwrites_and_leaves_no_partial_file(tmp_path):
    cap = fixtures.tiny_capture()
    path = write_capture(tmp_path / "c.hdf5", cap)
    before = path.read_bytes()
    with pytest.raises(DataError, match="already exists; refusing to overwrite"):
        write_capture(path, cap.replace(H=cap.H * 2))
    assert path.read_bytes() == before

    with pytest.raises(RuntimeError), atomic_path(tmp_path / "x.bin") as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("writer failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.hdf5"]


def test_phasor_field_and_reconstruction_round_trip(tmp_path):
    field = fixtures.point_phasor_field(frequencies=(3.0, 4.0), confocal=True)
    field = field.replace(weights=np.array([1 + 1j, 0.5]), metadata={"a": [1, 2]})
    again = read_phasor_field(write_phasor_field(tmp_path / "f.hdf5", field))
    np.testing.assert_array_equal(again.values, field.values)
    np.testing.assert_array_equal(again.weights, field.weights)
    np.testing.assert_array_equal(again.wall_xyz, field.wall_xyz)
    assert again.geometry.kind is CaptureKind.CONFOCAL and again.metadata == {"a": [1, 2]}

    vox = fixtures.tiny_voxels(n=4)
    recon = Reconstruction(np.arange(48.0).reshape(3, 4, 4), vox, {"imager": "x"})
    back = read_reconstruction(write_reconstruction(tmp_path / "r.hdf5", recon))
    np.testing.assert_array_equal(back.intensity, recon.intensity)
    np.testing.assert_array_equal(back.voxels, recon.voxels)
    with pytest.raises(DataError, match="holds Reconstruction, expected a PhasorField file"):
        read_phasor_field(tmp_path / "r.hdf5")


def test_field_file_mismatch_is_reported(tmp_path):
    field = fixtures.point_phasor_field()
    path = write_phasor_field(tmp_path / "f.hdf5", field)
    with h5py.File(path, "a") as f:
        del f["frequencies"]
        f["frequencies"] = np.array([1.0, 2.0])
    with pytest.raises(DataError, match="frequencies: 2 given for 1 field slices"):
        read_phasor_field(path)


def test_capture_layout_single_spot(tmp_path):
    cap = read_capture(DATA / "ytal_single.hdf5")
    assert cap.H_format is HFormat.T_Sx_Sy
    np.testing.assert_allclose(cap.laser_point, [0.1, -0.05, 0.0], atol=1e-7)

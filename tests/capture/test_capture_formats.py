"""Capture formats: each published layout, written here from a simulated capture, reads back
as that capture (values, wall points, units, time origin); detection from content; bad
files and options refused in one line."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from nlosfw import CaptureKind, DataError, GridFormat, HFormat
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.capture.hdf5 import write_capture
from nlosfw.capture.preprocess import as_scan_grid
from nlosfw.capture.source import CaptureSource, load_file_capture
from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError
from nlosfw.plugins import load_plugins
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import layouts

DATA = Path(__file__).resolve().parents[1] / "data"
#: An asymmetric target, so that a mirrored or transposed reader is caught.
TARGET = (0.25, -0.15, 0.6)


@pytest.fixture(scope="module")
def host():
    return load_plugins()


def source(**options):
    """``capture.*`` options as the command line gives them."""
    return config_from_mapping(CaptureSource, options, "capture")


def simulate(config, target=TARGET):
    config = {**config, "geometry": [{"type": "patch", "position": list(target),
                                      "size": [0.04, 0.04]}]}
    return AnalyticSimulator().simulate(scene_from_config(config))


def formats(host):
    """Every installed capture format by name (those detection asks)."""
    catalogue = host.capture_formats()
    return {name: catalogue.create(name) for name in sorted(catalogue.installed)}


def claimed_by(host, path):
    return [name for name, fmt in formats(host).items() if fmt.detect(path)]


def nearest_pixel(capture, xy):
    """Index (X, Y) of the wall point nearest ``xy``."""
    d = np.linalg.norm(capture.sensor_grid_xyz[..., :2] - np.asarray(xy), axis=-1)
    return np.unravel_index(int(np.argmin(d)), d.shape)


def first_arrival_pixel(capture):
    """The scan point whose histogram starts earliest: the one nearest the hidden patch."""
    first = np.argmax(capture.H > 0, axis=0).astype(float)
    first[~np.any(capture.H > 0, axis=0)] = np.inf
    return np.unravel_index(int(np.argmin(first)), first.shape)


# ----------------------------------------------------------------------------- Stanford LCT
@pytest.fixture(scope="module")
def lct_capture():
    return simulate(layouts.lct_scene())


def counts(capture, peak=1000):
    """The capture as photon counts (integers), as the published uint16 files hold."""
    return capture.replace(H=np.rint(capture.H / capture.H.max() * peak).astype(np.float32))


def test_lct_file_reads_back_as_the_simulated_capture(tmp_path, host, lct_capture):
    known = counts(lct_capture)
    path = layouts.write_lct(tmp_path / "data_s_u.mat", known, dtype=np.uint16)
    assert path.read_bytes()[:19] == b"MATLAB 5.0 MAT-file"
    raw = scipy.io.loadmat(path)
    assert raw["rect_data"].dtype == np.uint16 and raw["rect_data"].shape == (8, 8, 1700)
    assert raw["width"].shape == (1, 1) and raw["width"][0, 0] == pytest.approx(0.5)
    assert claimed_by(host, path) == ["lct"]
    got = formats(host)["lct"].read(path)
    np.testing.assert_array_equal(got.H, known.H)
    np.testing.assert_allclose(got.sensor_grid_xyz, known.sensor_grid_xyz, atol=1e-12)
    assert got.kind is CaptureKind.CONFOCAL and got.H_format is HFormat.T_Sx_Sy
    assert got.delta_t == pytest.approx(4e-12 * SPEED_OF_LIGHT, rel=1e-12)  # 1.199 mm
    assert got.t_start == 0.0 and not got.t_accounts_first_and_last_bounces
    # physics: the earliest light comes back at the wall point in front of the patch,
    # at twice its depth
    assert first_arrival_pixel(got) == nearest_pixel(got, TARGET[:2])
    i, j = first_arrival_pixel(got)
    onset = got.bin_centers[np.argmax(got.H[:, i, j] > 0)]
    x = got.sensor_grid_xyz[i, j]
    assert onset == pytest.approx(2 * np.linalg.norm(np.subtract(TARGET, x)), abs=0.03)


def test_lct_defaults_gate_the_direct_reflection_as_the_authors(tmp_path, host, lct_capture):
    path = layouts.write_lct(tmp_path / "scene.mat", counts(lct_capture), dtype=np.uint16)
    assert formats(host)["lct"].defaults(path).gate.bins == 600
    loaded = load_file_capture(source(path=str(path)), host.capture_formats())
    (step,) = loaded.prepared.steps
    assert (step.option, step.value, step.source) == ("gate", {"bins": 600}, "format")
    assert np.all(loaded.prepared.capture.H[:600] == 0)
    assert np.array_equal(loaded.prepared.capture.H[600:], counts(lct_capture).H[600:])
    # the user's option wins over the format's default
    loaded = load_file_capture(source(path=str(path), gate={"bins": 0}), host.capture_formats())
    assert loaded.prepared.steps[0].source == "option"
    np.testing.assert_array_equal(loaded.prepared.capture.H, counts(lct_capture).H)


# ------------------------------------------------------------------------------ Stanford f-k
@pytest.fixture(scope="module")
def fk_capture():
    return simulate(layouts.fk_scene())


@pytest.mark.parametrize("tof_version", [5, 73])
def test_fk_file_with_tof_reads_back_as_the_simulated_capture(tmp_path, host, fk_capture,
                                                              tof_version):
    rng = np.random.default_rng(1)
    delays = rng.uniform(0, 1500, fk_capture.grid_shape)              # ps, on (X, Y)
    meas, tof = layouts.write_fk(tmp_path, fk_capture, delays, tof_version=tof_version)
    with h5py.File(meas, "r") as f:                 # MATLAB v7.3: HDF5, axes reversed
        assert f["meas"].shape == (330, 8, 8)
    assert meas.read_bytes()[:19] == b"MATLAB 7.3 MAT-file"
    assert claimed_by(host, meas) == ["fk"] and claimed_by(host, tof) == []
    loaded = load_file_capture(source(path=str(meas)), host.capture_formats())
    got = loaded.prepared.capture
    (step,) = loaded.prepared.steps                                   # 330 bins: no crop
    assert (step.option, step.value, step.source) == ("tofgrid", str(tof), "format")
    shifts = np.floor(delays / 32).astype(int)
    assert step.effect == (f"histograms shifted left by {shifts.min()} to {shifts.max()} "
                           "bins")
    keep = got.n_bins - shifts.max()
    np.testing.assert_allclose(got.H[:keep], fk_capture.H[:keep], rtol=1e-6, atol=0)
    np.testing.assert_allclose(got.sensor_grid_xyz, fk_capture.sensor_grid_xyz, atol=1e-12)
    assert got.delta_t == pytest.approx(32e-12 * SPEED_OF_LIGHT, rel=1e-12)
    assert got.t_start == 0.0 and got.kind is CaptureKind.CONFOCAL
    assert first_arrival_pixel(got) == nearest_pixel(got, TARGET[:2])


def test_fk_without_tof_warns_and_crops_to_512_bins(tmp_path, host, caplog):
    capture = simulate(layouts.fk_scene(bins=600))
    meas, _ = layouts.write_fk(tmp_path, capture)
    with caplog.at_level(logging.WARNING):
        loaded = load_file_capture(source(path=str(meas)), host.capture_formats())
    assert "no tof.mat beside it" in caplog.text
    (step,) = loaded.prepared.steps
    assert (step.option, step.value, step.source) == ("time_crop", {"bins": [0, 512]}, "format")
    np.testing.assert_allclose(loaded.prepared.capture.H, capture.H[:512], rtol=1e-6)


def test_tofgrid_whose_shape_differs_is_one_line_naming_file_and_variable(tmp_path, host,
                                                                          fk_capture):
    meas, _ = layouts.write_fk(tmp_path, fk_capture)
    layouts.write_mat5(tmp_path / "tof.mat", {"tofgrid": np.zeros((4, 4))})
    with pytest.raises(ConfigError) as info:
        load_file_capture(source(path=str(meas)), host.capture_formats())
    assert str(info.value) == (f"capture.tofgrid: {tmp_path / 'tof.mat'}: variable 'tofgrid' "
                               f"has shape [4, 4]; expected [8, 8], the scan grid of {meas}")


# --------------------------------------------------------------------- Wisconsin / Zaragoza
@pytest.fixture(scope="module")
def wisconsin_capture():
    return simulate(layouts.wisconsin_scene())


def test_wisconsin_file_reads_as_ytal_converts_it(tmp_path, host, wisconsin_capture):
    known = wisconsin_capture
    path = layouts.write_wisconsin(tmp_path / "performat_letter4.mat", known)
    with h5py.File(path, "r") as f:  # the shapes y-tal's converter expects from h5py
        assert f["dataset/data"].shape == (400, 1, 64)
        assert f["dataset/laserPos"].shape == (3, 64)
    assert claimed_by(host, path) == ["wisconsin"]
    got = formats(host)["wisconsin"].read(path)
    assert got.H_format is HFormat.T_Si and got.sensor_grid_format is GridFormat.N_3
    assert got.laser_grid_format is GridFormat.N_3 and got.kind is CaptureKind.SINGLE_SPOT
    np.testing.assert_allclose(got.H, known.H.reshape(known.n_bins, -1), rtol=1e-6)
    np.testing.assert_allclose(got.sensor_grid_xyz, known.sensor_points, atol=1e-12)
    np.testing.assert_allclose(got.sensor_xyz, known.sensor_xyz)            # laserOrigin
    np.testing.assert_allclose(got.laser_xyz, known.laser_point)            # cameraPos
    np.testing.assert_allclose(got.laser_grid_xyz, known.laser_point.reshape(1, 3))
    assert got.t_accounts_first_and_last_bounces and got.delta_t == known.delta_t
    # same time origin: the optical path minus the device legs at every wall point
    np.testing.assert_allclose(
        got.t_start - got.geometry.device_path(got.sensor_points),
        known.t_start - known.geometry.device_path(known.sensor_points), atol=1e-12)
    assert got.scene_info["original_format"] == "MAT_PHASOR_FIELDS"
    assert set(got.scene_info["volume"]) == {"minimal_pos", "maximal_pos",
                                             "sampling_grid_spacing"}
    # the listed laser positions form the 8 x 8 grid the scene scanned
    grid = as_scan_grid(got)
    assert grid is not None and grid.H_format is HFormat.T_Sx_Sy
    np.testing.assert_allclose(grid.H, known.H, rtol=1e-6)
    np.testing.assert_allclose(grid.sensor_grid_xyz, known.sensor_grid_xyz, atol=1e-12)


def test_wisconsin_points_stored_three_by_n_read_the_same(tmp_path, host, wisconsin_capture):
    path = layouts.write_wisconsin(tmp_path / "a.mat", wisconsin_capture)
    other = tmp_path / "b.mat"
    shutil.copy(path, other)
    with h5py.File(other, "a") as f:        # MATLAB 3 x nl instead of nl x 3
        for name in ("laserPos", "laserNorm"):
            value = f[f"dataset/{name}"][()]
            del f[f"dataset/{name}"]
            f[f"dataset/{name}"] = value.T
    a, b = (formats(host)["wisconsin"].read(p) for p in (path, other))
    np.testing.assert_array_equal(a.sensor_grid_xyz, b.sensor_grid_xyz)
    np.testing.assert_array_equal(a.sensor_grid_normals, b.sensor_grid_normals)


def test_znlos_file_reads_back_as_the_simulated_capture(tmp_path, host):
    known = simulate(layouts.znlos_scene())
    path = layouts.write_znlos(tmp_path / "bunny_conf.hdf5", known)
    assert claimed_by(host, path) == ["znlos"]
    got = formats(host)["znlos"].read(path)
    np.testing.assert_allclose(got.H, known.H, rtol=1e-6)
    np.testing.assert_allclose(got.sensor_grid_xyz, known.sensor_grid_xyz, atol=1e-12)
    assert got.t_accounts_first_and_last_bounces and got.kind is CaptureKind.CONFOCAL
    np.testing.assert_allclose(got.geometry.device_path(got.sensor_points),
                               known.geometry.device_path(known.sensor_points), atol=1e-12)


# ----------------------------------------------------------------------------- y-tal, nlosfw
def test_ytal_and_nlosfw_files_are_told_apart_by_the_attribute_only(tmp_path, host):
    assert claimed_by(host, DATA / "ytal_single.hdf5") == ["ytal"]       # written by y-tal
    assert claimed_by(host, DATA / "znlos_confocal.hdf5") == ["znlos"]
    capture = layouts.known_captures(host.registry.get("capture_format", "nlosfw"))[0]
    ours = write_capture(tmp_path / "ours.hdf5", capture)
    theirs = formats(host)["ytal"].write(tmp_path / "theirs.hdf5", capture)
    assert claimed_by(host, ours) == ["nlosfw"] and claimed_by(host, theirs) == ["ytal"]
    with h5py.File(ours, "r") as a, h5py.File(theirs, "r") as b:
        assert set(a) == set(b) and dict(a.attrs) != dict(b.attrs) == {}
    forced = formats(host)["ytal"].read(ours)  # one reader: either reads the other's files
    np.testing.assert_array_equal(forced.H, capture.H)


# ---------------------------------------------------------------------------- detection
def test_detection_uses_content_not_the_file_name(tmp_path, host, lct_capture):
    path = layouts.write_lct(tmp_path / "scene.mat", lct_capture)
    renamed = tmp_path / "scene.hdf5"
    path.rename(renamed)
    assert claimed_by(host, renamed) == ["lct"]
    loaded = load_file_capture(source(path=str(renamed), gate={"bins": 0}), host.capture_formats())
    assert loaded.format == "lct"


def test_unknown_file_lists_the_supported_formats(tmp_path, host):
    path = layouts.write_mat5(tmp_path / "image.mat", {"image": np.zeros((3, 3))})
    with pytest.raises(DataError) as info:
        load_file_capture(source(path=str(path)), host.capture_formats())
    assert str(info.value) == (f"{path}: not a capture file of any supported format; "
                               "supported: fk, lct, nlosfw, wisconsin, ytal, znlos (force one "
                               "with capture.format=NAME)")


# ---------------------------------------------------------------------------- bad input
def test_mat_without_width_is_not_lct_and_forcing_names_the_variable(tmp_path, host):
    path = layouts.write_mat5(tmp_path / "cut.mat", {"rect_data": np.zeros((4, 4, 8))})
    assert claimed_by(host, path) == []
    with pytest.raises(DataError) as info:
        load_file_capture(source(path=str(path), format="lct"), host.capture_formats())
    assert str(info.value).startswith(f"{path}: no variable 'width' (expected rect_data, the "
                                      "histograms [N, N, T] (uint16, 4 ps bins), and width")


@pytest.mark.parametrize("width", [-0.5, 0.0])
def test_lct_width_must_be_positive(tmp_path, host, width):
    path = layouts.write_mat5(tmp_path / "w.mat", {"rect_data": np.zeros((4, 4, 8)),
                                                   "width": np.array([[width]])})
    with pytest.raises(DataError) as info:
        formats(host)["lct"].read(path)
    assert str(info.value) == (f"{path}: variable 'width' is {width}; expected a positive "
                               "number of metres (half the side of the scanned square)")


def test_forcing_another_format_names_the_missing_variable(tmp_path, host, fk_capture):
    meas, _ = layouts.write_fk(tmp_path, fk_capture)
    with pytest.raises(DataError) as info:
        load_file_capture(source(path=str(meas), format="lct"), host.capture_formats())
    assert str(info.value).startswith(f"{meas}: no variable 'rect_data' (expected rect_data, ")
    assert str(info.value).endswith("the file holds: meas)")
    with pytest.raises(DataError, match=r"no struct 'dataset' \(expected a struct 'dataset'"):
        load_file_capture(source(path=str(meas), format="wisconsin"), host.capture_formats())
    with pytest.raises(ConfigError, match=r"^capture.format: unknown capture format 'tal'; "
                                          r"valid: fk, lct, nlosfw, wisconsin, ytal, znlos$"):
        load_file_capture(source(path=str(meas), format="tal"), host.capture_formats())


def test_gate_past_the_end_names_the_option_and_the_valid_range(tmp_path, host, lct_capture):
    path = layouts.write_lct(tmp_path / "s.mat", lct_capture)
    with pytest.raises(ConfigError) as info:
        load_file_capture(source(path=str(path), gate={"metres": 2.5}), host.capture_formats())
    assert str(info.value).startswith("capture.gate.metres: 2.5 m is past the end of the "
                                      "histogram (1700 bins, path 0 to 2.039 m); valid: fewer "
                                      "than 1700 bins (0: no gate)")
    short = layouts.write_lct(tmp_path / "short.mat", lct_capture.replace(
        H=lct_capture.H[:500]))
    with pytest.raises(ConfigError) as info:     # the format's own default does not fit
        load_file_capture(source(path=str(short)), host.capture_formats())
    assert str(info.value).endswith("(the capture format's default; set capture.gate to "
                                    "override it)")


@pytest.mark.parametrize("name", ["nlosfw", "ytal", "znlos", "lct", "fk", "wisconsin"])
def test_every_builtin_format_sizes_its_file_from_the_header(tmp_path, host, name):
    """transient_shape (the memory estimate's input) is known for every built-in layout and
    is the shape the file reads as; nothing else in the file is needed for it."""
    from nlosfw.testing.layouts import known_captures, write_sample

    spec = host.registry.get("capture_format", name)
    fmt = spec.create({})
    known = known_captures(spec)[0]
    path = write_sample(spec, fmt, known, tmp_path)
    shape = fmt.transient_shape(path)
    read = fmt.read(path)
    assert shape is not None
    bins, sensors, lasers = shape
    assert (bins, sensors * lasers) == (read.n_bins, read.H.size // read.n_bins)
    if name == "lct":                             # layouts.lct_scene: 8 x 8 scan, 1700 bins
        assert shape == (1700, 64, 1)

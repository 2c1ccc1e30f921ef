"""Preprocessing of captures: each step checked against physics (a mirrored scene simulated
directly, closed-form arrival times) or by hand; inputs are never modified."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.capture.enums import GridFormat, HFormat
from nlosfw.capture.preprocess import (
    METRES_PER_PS,
    BinWidth,
    Extras,
    FlipAxes,
    Gate,
    Preprocessing,
    TimeCrop,
    as_scan_grid,
    bin_scan,
    crop_time,
    flip_scan,
    preprocess,
    remove_delays,
    stride_scan,
    transpose_scan,
)
from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing.fixtures import tiny_scene_config
from nlosfw.testing.layouts import delay_histograms


def simulate(target=(0.2, 0.1, 0.6), confocal=False, legs=False, resolution=8):
    config = tiny_scene_config(confocal=confocal, device_legs=legs, bins=400,
                               resolution=resolution, target=target)
    if legs:
        config["capture"]["laser_position"] = [0.3, -0.2, 0.4]
        config["capture"]["sensor_position"] = [-0.6, 0.1, 0.3]
    return AnalyticSimulator().simulate(scene_from_config(config))


def options(**kwargs):
    return config_from_mapping(Preprocessing, kwargs, "capture")


def frozen(capture):
    capture.H.setflags(write=False)
    return capture


@pytest.mark.parametrize("confocal", [False, True])
def test_flip_x_is_the_mirrored_scene(confocal):
    """Mirroring the scan along x gives the capture of the scene mirrored in x = 0 (laser
    spot at the wall's centre, so the mirror maps the setup onto itself)."""
    capture = frozen(simulate(confocal=confocal))
    mirrored = simulate(target=(-0.2, 0.1, 0.6), confocal=confocal)
    assert not np.allclose(capture.H, mirrored.H, rtol=0.1)  # the mirror is seen
    flipped = flip_scan(capture, FlipAxes.x)
    np.testing.assert_allclose(flipped.H, mirrored.H, rtol=1e-5, atol=1e-12 * capture.H.max())
    np.testing.assert_allclose(flipped.sensor_grid_xyz, capture.sensor_grid_xyz)
    both = flip_scan(capture, FlipAxes.xy)
    np.testing.assert_allclose(both.H, simulate(target=(-0.2, -0.1, 0.6), confocal=confocal).H,
                               rtol=1e-5, atol=1e-12 * capture.H.max())


def test_flip_mirrors_the_device_legs_too():
    capture = frozen(simulate(legs=True))
    flipped = flip_scan(capture, FlipAxes.y)
    np.testing.assert_allclose(flipped.laser_xyz, [0.3, 0.2, 0.4])
    np.testing.assert_allclose(flipped.sensor_xyz, [-0.6, -0.1, 0.3])
    # every wall point keeps its path minus legs: the legs moved with the data
    legs = flipped.geometry.device_path(flipped.sensor_grid_xyz)
    np.testing.assert_allclose(legs[:, ::-1], capture.geometry.device_path(
        capture.sensor_grid_xyz), rtol=1e-12)


def test_transpose_is_the_scene_mirrored_in_the_diagonal():
    capture = frozen(simulate(confocal=True))
    swapped = simulate(target=(0.1, 0.2, 0.6), confocal=True)
    assert not np.allclose(capture.H, swapped.H, rtol=0.1)
    np.testing.assert_allclose(transpose_scan(capture).H, swapped.H, rtol=1e-5,
                               atol=1e-12 * capture.H.max())


def test_bin_sums_blocks_at_their_mean_position():
    capture = frozen(simulate(confocal=True))
    binned = bin_scan(capture, 2)
    assert binned.grid_shape == (4, 4) and binned.is_confocal
    np.testing.assert_allclose(binned.H[:, 1, 2], capture.H[:, 2:4, 4:6].sum(axis=(1, 2)),
                               rtol=1e-6)
    coarse = simulate(confocal=True, resolution=4)       # the 4 x 4 grid of the same wall
    np.testing.assert_allclose(binned.sensor_grid_xyz, coarse.sensor_grid_xyz, atol=1e-12)
    with pytest.raises(ConfigError, match=r"^capture.bin: 3 does not divide the scan grid 8x8"):
        bin_scan(capture, 3)


def test_stride_keeps_every_kth_point():
    capture = frozen(simulate())
    kept = stride_scan(capture, 2)
    np.testing.assert_array_equal(kept.H, capture.H[:, ::2, ::2])
    np.testing.assert_array_equal(kept.sensor_grid_xyz, capture.sensor_grid_xyz[::2, ::2])
    assert kept.laser_point.tolist() == capture.laser_point.tolist()


def test_gate_and_crop_keep_the_time_axis_physical():
    capture = frozen(simulate())
    out, steps = preprocess(capture, options(gate={"metres": 1.0}, time_crop={"bins": [50, 300]}))
    # bins starting before 1.0 m are zero: 0.01 m bins from 0 -> bins 0..99
    assert [s.option for s in steps] == ["gate", "time_crop"]
    assert steps[0].effect == "zeroed bins 0 to 99 (path < 1 m)"
    assert out.t_start == pytest.approx(0.5) and out.n_bins == 250
    np.testing.assert_array_equal(out.H[:50], 0)
    np.testing.assert_array_equal(out.H[50:], capture.H[100:300])
    np.testing.assert_allclose(out.bin_centers, capture.bin_centers[50:300])
    cropped = crop_time(capture, 0, 10)
    assert cropped.t_start == capture.t_start and cropped.n_bins == 10


def test_time_crop_in_metres_keeps_the_overlapping_bins():
    capture = frozen(simulate())
    out, _ = preprocess(capture, options(time_crop={"metres": [1.005, 2.0]}))
    assert out.t_start == pytest.approx(1.0) and out.n_bins == 100


def test_delays_removed_bring_back_the_capture():
    capture = frozen(simulate(confocal=True))
    rng = np.random.default_rng(3)
    delays = rng.uniform(0, 400, capture.grid_shape)
    bin_ps = capture.delta_t / METRES_PER_PS
    delayed = capture.replace(H=delay_histograms(capture, delays, bin_ps))
    fixed, shifts = remove_delays(delayed, delays)
    np.testing.assert_array_equal(shifts, np.floor(delays / bin_ps))
    keep = capture.n_bins - shifts.max()
    np.testing.assert_array_equal(fixed.H[:keep], capture.H[:keep])


def test_background_and_bin_width():
    capture = frozen(simulate())
    background = capture.replace(H=np.full_like(capture.H, 0.25 * capture.H.max()))
    out, steps = preprocess(capture, options(background="bg.hdf5", bin_width={"ps": 20.0}),
                            extras=Extras(background=background))
    assert [s.option for s in steps] == ["background", "bin_width"]
    np.testing.assert_allclose(out.H, capture.H - 0.25 * capture.H.max())
    assert out.delta_t == pytest.approx(20e-12 * 299_792_458.0)


def test_steps_run_in_order_and_record_values_and_sources():
    capture = frozen(simulate(confocal=True))
    user = options(stride=2, flip="x")
    merged, from_format = user.merged_over(Preprocessing(gate=Gate(bins=5), stride=4))
    assert merged.stride == 2 and merged.gate.bins == 5 and from_format == {"gate"}
    out, steps = preprocess(capture, merged, from_format)
    assert [(s.option, s.value, s.source) for s in steps] == [
        ("gate", {"bins": 5}, "format"), ("flip", "x", "option"), ("stride", 2, "option")]
    assert out.scene_info["preprocessing"][-1]["option"] == "stride"
    assert "preprocessing" not in capture.scene_info


def test_a_listed_grid_becomes_the_grid():
    capture = frozen(simulate())
    order = np.random.default_rng(0).permutation(64)
    listed = capture.replace(H=capture.H.reshape(capture.n_bins, -1)[:, order],
                             H_format=HFormat.T_Si,
                             sensor_grid_xyz=capture.sensor_points[order],
                             sensor_grid_normals=capture.sensor_grid_normals.reshape(-1, 3)[order],
                             sensor_grid_format=GridFormat.N_3)
    grid = as_scan_grid(listed)
    np.testing.assert_array_equal(grid.H, capture.H)
    np.testing.assert_array_equal(grid.sensor_grid_xyz, capture.sensor_grid_xyz)
    out, steps = preprocess(listed, Preprocessing())
    assert [(s.option, s.source) for s in steps] == [("grid", "automatic")]
    irregular = listed.replace(sensor_grid_xyz=listed.sensor_grid_xyz * [1, 1, 0] +
                               [0, 0, 0.05])
    assert as_scan_grid(irregular) is None      # off the wall plane: left as a list


@pytest.mark.parametrize(("mapping", "message"), [
    ({"gate": {"bins": 3, "metres": 0.5}}, "capture.gate.bins: give the gate in bins or in "
                                           "metres, not both"),
    ({"time_crop": {"bins": [5, 5]}}, "capture.time_crop.bins: must satisfy 0 <= start < stop"),
    ({"bin_width": {"ps": -4}}, "capture.bin_width.ps: must be > 0, got -4.0"),
    ({"stride": 0}, "capture.stride: must be >= 1, got 0"),
    ({"flip": "z"}, "capture.flip: must be one of 'x', 'y', 'xy', got 'z'"),
])
def test_bad_options_name_the_option(mapping, message):
    with pytest.raises(ConfigError) as info:
        options(**mapping)
    assert str(info.value).startswith(message)


def test_crop_outside_the_histogram_is_refused():
    capture = simulate()
    with pytest.raises(ConfigError, match=r"^capture.time_crop.bins: keeps bins \[390, 500\), "
                                          r"outside the histogram \(400 bins"):
        preprocess(capture, Preprocessing(time_crop=TimeCrop(bins=(390, 500))))
    assert BinWidth(metres=0.01).in_metres == 0.01

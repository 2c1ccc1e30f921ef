"""Capture validation and geometry, against values computed by hand."""

import numpy as np
import pytest

from nlosfw import Capture, CaptureKind, DataError, GridFormat, HFormat


def grid(nx, ny):
    x, y = np.meshgrid(np.linspace(-0.5, 0.5, nx), np.linspace(-0.4, 0.4, ny), indexing="ij")
    return np.stack([x, y, np.zeros_like(x)], -1)


def make(**overrides):
    kwargs = dict(H=np.zeros((10, 3, 2), np.float32), H_format=HFormat.T_Sx_Sy,
                  sensor_grid_xyz=grid(3, 2), laser_grid_xyz=np.zeros((1, 1, 3)), delta_t=0.01)
    kwargs.update(overrides)
    return Capture(**kwargs)


def test_kinds_and_properties():
    single = make(t_start=0.5)
    assert single.kind is CaptureKind.SINGLE_SPOT
    np.testing.assert_allclose(single.bin_centers[:2], [0.505, 0.515])
    assert single.sensor_points.shape == (6, 3)
    np.testing.assert_array_equal(single.sensor_points[1], grid(3, 2)[0, 1])
    confocal = make(laser_grid_xyz=grid(3, 2))
    assert confocal.kind is CaptureKind.CONFOCAL and confocal.is_confocal
    exhaustive = make(H=np.zeros((10, 2, 2, 3, 2), np.float32), H_format=HFormat.T_Lx_Ly_Sx_Sy,
                      laser_grid_xyz=grid(2, 2))
    assert exhaustive.kind is CaptureKind.EXHAUSTIVE


def test_one_sensor_is_confocal_only_where_the_laser_is():
    one = np.array([[[0.3, 0.0, 0.0]]])
    apart = make(H=np.zeros((10, 1, 1), np.float32), sensor_grid_xyz=one,
                 laser_grid_xyz=np.zeros((1, 1, 3)))
    assert apart.kind is CaptureKind.SINGLE_SPOT
    together = make(H=np.zeros((10, 1, 1), np.float32), sensor_grid_xyz=one,
                    laser_grid_xyz=one.copy())
    assert together.kind is CaptureKind.CONFOCAL


def test_device_path_by_hand():
    laser_xyz, sensor_xyz = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    cap = make(t_accounts_first_and_last_bounces=True, laser_xyz=laser_xyz, sensor_xyz=sensor_xyz,
               laser_grid_xyz=np.array([[[0.0, 0.0, 0.0]]]))
    wall = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    # laser leg 1.0, sensor legs 1.0 and 1.0
    np.testing.assert_allclose(cap.geometry.device_path(wall), [2.0, 2.0])
    assert np.all(make().geometry.device_path(wall) == 0)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"H": np.full((10, 3, 2), np.nan, np.float32)}, "H: contains 60 NaN or inf values"),
        ({"delta_t": 0.0}, "delta_t: must be a positive number of metres, got 0.0"),
        ({"delta_t": -1}, "delta_t: must be a positive number"),
        ({"sensor_grid_xyz": grid(2, 3)}, "sensor_grid_xyz: grid shape (2, 3) does not match H's "
                                          "sensor axes (3, 2)"),
        ({"H": np.zeros((10, 6), np.float32)}, "H: has 2 axes but H_format T_Sx_Sy needs 3"),
        ({"laser_grid_xyz": np.zeros((2, 2, 3))}, "laser_grid_xyz: shape (2, 2) is neither one "
                                                  "point"),
        ({"sensor_grid_normals": np.zeros((3, 3, 3))}, "sensor_grid_normals: shape (3, 3, 3) "
                                                       "does not match"),
        ({"H": np.zeros((10, 3, 2), np.int32)}, "H: dtype int32 is not a float type"),
        ({"sensor_grid_format": GridFormat.N_3}, "sensor_grid_xyz: sensor_grid_format N_3 needs "
                                                 "shape (N, 3)"),
        ({"t_accounts_first_and_last_bounces": True}, "t_accounts_first_and_last_bounces: true "
                                                      "needs sensor_xyz and laser_xyz"),
    ],
)
def test_invalid_captures_name_the_field(overrides, message):
    with pytest.raises(DataError) as info:
        make(**overrides)
    assert str(info.value).startswith(message), str(info.value)
    assert "\n" not in str(info.value)


def test_capture_does_not_modify_callers_arrays():
    H = np.ones((10, 3, 2), np.float32)
    before = H.copy()
    cap = make(H=H)
    cap.replace(H=H * 2)
    np.testing.assert_array_equal(H, before)

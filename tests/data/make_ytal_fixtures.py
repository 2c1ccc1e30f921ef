"""Regenerate the y-tal fixture captures (run with y-tal's own interpreter, numpy < 2).

    /path/to/ytal-venv/bin/python tests/data/make_ytal_fixtures.py tests/data

Writes, with ``tal.io.write_capture``:
- ``ytal_single.hdf5``: single laser spot, 6x4 sensor grid, 64 bins, device legs counted,
  scene_info holding numpy arrays (y-tal dumps them as numpy-tagged YAML);
- ``ytal_confocal.hdf5``: confocal 5x5 scan, gzip-compressed H, ``t_start`` stored as None;
- ``znlos_confocal.hdf5``: a file in the Zaragoza NLOS dataset layout (HDF5_ZNLOS, 5-axis
  ``data``), converted by y-tal on reading;
- ``ytal_expected.npz``: what y-tal itself reads back from each file (for the ZNLOS file, what
  its conversion function returns: y-tal 0.20's read_capture fails on ZNLOS files), for the
  tests to compare.
The H values are a deterministic function of the indices so the fixtures are tiny to store.
"""

import sys
from pathlib import Path

import h5py
import numpy as np
import tal
from tal.enums import GridFormat, HFormat, VolumeFormat
from tal.io.capture_data import NLOSCaptureData


def grid(nx, ny, size=1.0):
    xs = (np.arange(nx) + 0.5) * size / nx - size / 2
    ys = (np.arange(ny) + 0.5) * size / ny - size / 2
    x, y = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([x, y, np.zeros_like(x)], -1).astype(np.float32)


def single(out):
    d = NLOSCaptureData()
    nx, ny, nt = 6, 4, 64
    t, i, j = np.meshgrid(np.arange(nt), np.arange(nx), np.arange(ny), indexing="ij")
    d.H = (np.exp(-((t - 20 - i - 2 * j) ** 2) / 4.0) * (1 + i + 10 * j)).astype(np.float32)
    d.H_format = HFormat.T_Sx_Sy
    d.sensor_xyz = np.array([-0.5, 0.0, 0.25], np.float32)
    d.laser_xyz = np.array([-0.4, 0.1, 0.3], np.float32)
    d.sensor_grid_xyz = grid(nx, ny)
    d.sensor_grid_normals = np.broadcast_to(np.array([0, 0, 1], np.float32), (nx, ny, 3)).copy()
    d.sensor_grid_format = GridFormat.X_Y_3
    d.laser_grid_xyz = np.array([0.1, -0.05, 0.0], np.float32).reshape(1, 1, 3)
    d.laser_grid_normals = np.array([0, 0, 1], np.float32).reshape(1, 1, 3)
    d.laser_grid_format = GridFormat.X_Y_3
    d.volume_format = VolumeFormat.X_Y_Z_3
    d.delta_t = 0.01
    d.t_start = 1.5
    d.t_accounts_first_and_last_bounces = True
    d.scene_info = {"original_format": "test-fixture",
                    "volume": {"center": np.array([0.0, 0.0, 1.0]), "size": [1.0, 1.0, 0.5]},
                    "note": None}
    tal.io.write_capture(str(out / "ytal_single.hdf5"), d)


def confocal(out):
    d = NLOSCaptureData()
    n, nt = 5, 48
    t, i, j = np.meshgrid(np.arange(nt), np.arange(n), np.arange(n), indexing="ij")
    d.H = ((t == 10 + i + j) * (1.0 + i - 0.5 * j)).astype(np.float32)
    d.H_format = HFormat.T_Sx_Sy
    d.sensor_xyz = np.array([0.0, -0.6, 0.4], np.float32)
    d.laser_xyz = np.array([0.0, -0.6, 0.4], np.float32)
    g = grid(n, n, 0.8)
    d.sensor_grid_xyz = g
    d.laser_grid_xyz = g.copy()
    d.sensor_grid_normals = np.broadcast_to(np.array([0, 0, 1], np.float32), g.shape).copy()
    d.laser_grid_normals = d.sensor_grid_normals.copy()
    d.sensor_grid_format = GridFormat.X_Y_3
    d.laser_grid_format = GridFormat.X_Y_3
    d.volume_format = VolumeFormat.UNKNOWN
    d.delta_t = 0.02
    d.t_start = None
    d.t_accounts_first_and_last_bounces = False
    d.scene_info = {"original_format": "test-fixture-confocal"}
    tal.io.write_capture(str(out / "ytal_confocal.hdf5"), d, compression_level=4)


def znlos(out):
    # Zaragoza layout: confocal data (colors, t, bounces, sx, sy), grids stored as (3, Y, X)
    n, nt = 4, 32
    c, t, b, i, j = np.meshgrid(np.arange(1), np.arange(nt), np.arange(2), np.arange(n),
                                np.arange(n), indexing="ij")
    data = ((t == 5 + i + 2 * j + b) * (1.0 + i + n * j)).astype(np.float32)
    g = grid(n, n, 1.0)
    with h5py.File(out / "znlos_confocal.hdf5", "w") as f:
        f["data"] = data
        f["deltaT"] = 0.01
        f["t0"] = 0.0
        f["cameraPosition"] = np.array([[0.0], [0.0], [0.5]])
        f["laserPosition"] = np.array([[0.1], [0.0], [0.5]])
        f["cameraGridPositions"] = np.transpose(g)
        f["cameraGridNormals"] = np.transpose(np.broadcast_to([0.0, 0.0, 1.0], g.shape))
        f["laserGridPositions"] = np.transpose(g)
        f["laserGridNormals"] = np.transpose(np.broadcast_to([0.0, 0.0, 1.0], g.shape))
        f["hiddenVolumePosition"] = np.array([[0.0], [0.0], [0.8]])
        f["hiddenVolumeRotation"] = np.array([[0.0], [0.0], [0.0]])
        f["hiddenVolumeSize"] = np.array([[0.6]])


def expected(out):
    arrays = {}
    from tal.enums import FileFormat
    from tal.io.capture_data import read_hdf5
    from tal.io.format import convert_dict

    for name in ("ytal_single", "ytal_confocal", "znlos_confocal"):
        if name.startswith("znlos"):
            # y-tal 0.20's read_capture crashes on ZNLOS files (it passes the converted
            # scene_info dict to yaml.load); its conversion function is the reference.
            r = NLOSCaptureData()
            for key, value in convert_dict(read_hdf5(str(out / f"{name}.hdf5")),
                                           FileFormat.HDF5_TAL).items():
                setattr(r, key, value)
        else:
            r = tal.io.read_capture(str(out / f"{name}.hdf5"))
        arrays[f"{name}.H"] = np.asarray(r.H)
        arrays[f"{name}.sensor_grid_xyz"] = np.asarray(r.sensor_grid_xyz)
        arrays[f"{name}.laser_grid_xyz"] = np.asarray(r.laser_grid_xyz)
        arrays[f"{name}.delta_t"] = np.asarray(r.delta_t)
        arrays[f"{name}.H_format"] = np.asarray(r.H_format.value)
        arrays[f"{name}.is_confocal"] = np.asarray(r.is_confocal())
    np.savez_compressed(out / "ytal_expected.npz", **arrays)


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
    for make in (single, confocal, znlos, expected):
        make(target)

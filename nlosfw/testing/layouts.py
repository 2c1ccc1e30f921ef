"""Small files in the published capture layouts, written from a known capture.

The conformance kit and the tests check each reader against files written here, so these
writers follow the published layouts directly (index by index, from the sources the
readers' docstrings cite) and share no code with the readers: a reader whose axis order,
units or time origin drifts from the layout then disagrees with the simulation the
file was written from. Each writer refuses a capture its layout cannot hold.

* Stanford LCT (MATLAB v5, :func:`write_lct`): ``rect_data[i, j, t] = H[t, N-1-i, N-1-j]``,
  ``width`` = half the scanned side; 4 ps bins from the wall.
* Stanford f-k (MATLAB v7.3 = HDF5, :func:`write_fk`): ``meas[i, j, t] = H[t, j, N-1-i]``
  delayed per pixel by ``tofgrid[i, j]`` ps (``tof.mat``); 32 ps bins; 2 m square.
* Wisconsin phasor field (v7.3, :func:`write_wisconsin`): struct ``dataset`` as y-tal reads it.
* Zaragoza ZNLOS (HDF5, :func:`write_znlos`): confocal 5-axis ``data`` as y-tal reads it.

MATLAB v7.3 files are HDF5 with a 512-byte user block holding MATLAB's text header; an
``[A, B, C]`` MATLAB array is stored as an HDF5 dataset of shape ``(C, B, A)``.
"""

from __future__ import annotations

import unittest
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat
from nlosfw.capture.formats import CaptureFormat
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.plugins.capabilities import Capability as C
from nlosfw.plugins.registry import PluginSpec

#: Picoseconds of the LCT and f-k bins.
LCT_BIN_PS, FK_BIN_PS = 4.0, 32.0
_V73_HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 " \
              b"HDF5 schema 1.00 ."


class LayoutError(ValueError):
    """The capture cannot be written in this layout."""


# ------------------------------------------------------------------------ MATLAB writers
def write_mat5(path: Path, variables: dict[str, np.ndarray]) -> Path:
    """A MATLAB v5 file of ``variables`` (arrays in MATLAB's axis order)."""
    import scipy.io

    scipy.io.savemat(str(path), variables, format="5", do_compression=False)
    return path


def write_mat73(path: Path, variables: dict[str, Any]) -> Path:
    """A MATLAB v7.3 file: HDF5 after MATLAB's 512-byte header, every array stored with
    its axes reversed and its ``MATLAB_class``; a dict is a struct (an HDF5 group)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            _mat73_value(f, name, value)
    header = _V73_HEADER.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as f:
        f.write(header.ljust(512, b"\x00"))
    return path


def _mat73_value(parent: Any, name: str, value: Any) -> None:
    if isinstance(value, dict):
        group = parent.create_group(name)
        group.attrs["MATLAB_class"] = np.bytes_(b"struct")
        for key, item in value.items():
            _mat73_value(group, key, item)
        return
    arr = np.asarray(value)
    if arr.ndim < 2:
        arr = arr.reshape(1, -1) if arr.ndim == 1 else arr.reshape(1, 1)
    classes = {np.dtype(np.float64): b"double", np.dtype(np.float32): b"single",
               np.dtype(np.uint16): b"uint16", np.dtype(np.int32): b"int32"}
    ds = parent.create_dataset(name, data=arr.T)  # MATLAB [A, B, C] -> HDF5 (C, B, A)
    ds.attrs["MATLAB_class"] = np.bytes_(classes.get(arr.dtype, b"double"))


# ------------------------------------------------------------------------ layout checks
def _square_scan(capture: Capture, bin_ps: float, layout: str) -> tuple[int, float]:
    """(N, half width) of a confocal capture on a cell-centred N x N square centred at the
    origin, bins of ``bin_ps`` from the wall; LayoutError otherwise."""
    if capture.kind is not CaptureKind.CONFOCAL or capture.H_format is not HFormat.T_Sx_Sy:
        raise LayoutError(f"{layout} holds confocal scans on a grid")
    nx, ny = capture.grid_shape
    if nx != ny:
        raise LayoutError(f"{layout} holds square scans, got {nx}x{ny}")
    grid = capture.sensor_grid_xyz
    spacing = float(grid[1, 0, 0] - grid[0, 0, 0])
    half = nx * spacing / 2
    coords = -half + (np.arange(nx) + 0.5) * spacing
    expected = np.stack([*np.meshgrid(coords, coords, indexing="ij"), np.zeros((nx, nx))], -1)
    if not np.allclose(grid, expected, atol=1e-9):
        raise LayoutError(f"{layout} scans a cell-centred square centred at the origin")
    if not np.isclose(capture.delta_t, bin_ps * 1e-12 * SPEED_OF_LIGHT, rtol=1e-9):
        raise LayoutError(f"{layout} has {bin_ps} ps bins")
    if capture.t_start != 0 or capture.t_accounts_first_and_last_bounces:
        raise LayoutError(f"{layout} starts its time axis at the wall")
    return nx, half


# ------------------------------------------------------------------------------ layouts
def write_lct(path: Path, capture: Capture, dtype: npt.DTypeLike | None = None) -> Path:
    """``capture`` as a Stanford LCT file: ``rect_data`` [N, N, T] (``dtype``: e.g. uint16
    as published, default the capture's) and ``width``."""
    n, half = _square_scan(capture, LCT_BIN_PS, "the LCT layout")
    H = capture.H
    rect = np.empty((n, n, capture.n_bins), dtype=dtype or H.dtype)
    for i in range(n):
        for j in range(n):
            rect[i, j, :] = H[:, n - 1 - i, n - 1 - j]
    return write_mat5(path, {"rect_data": rect, "width": np.array([[half]])})


def delay_histograms(capture: Capture, delays_ps: np.ndarray, bin_ps: float) -> np.ndarray:
    """H (T, X, Y) with each scan point's histogram delayed by floor(delay / bin) bins
    (what a measurement holds before its per-pixel delays are removed)."""
    H = np.zeros_like(capture.H)
    shifts = np.floor(np.asarray(delays_ps) / bin_ps).astype(int)
    n = capture.n_bins
    for x in range(H.shape[1]):
        for y in range(H.shape[2]):
            s = shifts[x, y]
            H[s:, x, y] = capture.H[: n - s, x, y]
    return H


def write_fk(folder: Path, capture: Capture, delays_ps: np.ndarray | None = None,
             tof_version: int = 5) -> tuple[Path, Path | None]:
    """``capture`` as a Stanford f-k scan: ``folder/meas_10min.mat`` (v7.3) with ``meas``
    [N, N, T], and with ``delays_ps`` (X, Y) ``folder/tof.mat`` (``tof_version`` 5 or 73)
    holding ``tofgrid`` [N, N] in ps, the histograms delayed by it."""
    n, half = _square_scan(capture, FK_BIN_PS, "the f-k layout")
    if not np.isclose(half, 1.0):
        raise LayoutError("the f-k layout scans a 2 m x 2 m square")
    H = capture.H if delays_ps is None else delay_histograms(capture, delays_ps, FK_BIN_PS)
    meas = np.empty((n, n, capture.n_bins), dtype=np.float64)
    for i in range(n):
        for j in range(n):
            meas[i, j, :] = H[:, j, n - 1 - i]
    folder.mkdir(parents=True, exist_ok=True)
    data = write_mat73(folder / "meas_10min.mat", {"meas": meas})
    if delays_ps is None:
        return data, None
    tofgrid = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            tofgrid[i, j] = delays_ps[j, n - 1 - i]
    writer = write_mat5 if tof_version == 5 else write_mat73
    return data, writer(folder / "tof.mat", {"tofgrid": tofgrid})


def write_wisconsin(path: Path, capture: Capture) -> Path:
    """A single-spot capture whose time axis includes the device legs as a Wisconsin
    phasor-field file: by reciprocity the capture's sensors are the file's laser positions
    and its laser spot the file's camera point. The layout puts that device at its wall
    point (y-tal: ``laser_xyz = cameraPos``), so the capture's laser leg, one constant
    length for one spot, moves into ``t0``."""
    if capture.kind is not CaptureKind.SINGLE_SPOT or not capture.is_time_domain:
        raise LayoutError("the Wisconsin layout holds single-spot captures")
    spot = capture.laser_point
    if not capture.t_accounts_first_and_last_bounces or capture.sensor_xyz is None \
            or capture.laser_xyz is None:
        raise LayoutError("the Wisconsin layout counts the device legs")
    laser_leg = float(np.linalg.norm(capture.laser_xyz - spot))
    points = capture.sensor_points                              # (nl, 3)
    nl, nt = points.shape[0], capture.n_bins
    data = capture.H.reshape(nt, nl).T[:, None, :]              # MATLAB [nl, 1, nt]
    normals = (np.tile([0.0, 0.0, 1.0], (nl, 1)) if capture.sensor_grid_normals is None
               else capture.sensor_grid_normals.reshape(-1, 3))
    dataset = {
        "t": np.array([[float(nt)]]),
        "data": data.astype(np.float64),
        "laserOrigin": capture.sensor_xyz.reshape(1, 3),
        "laserPos": points,                                     # MATLAB nl x 3
        "laserNorm": normals,
        "cameraPos": spot.reshape(1, 3),
        "cameraNormal": np.array([[0.0, 0.0, 1.0]]),
        "deltat": np.array([[capture.delta_t]]),
        "t0": np.array([[capture.t_start - laser_leg]]),
    }
    lo, hi = points.min(axis=0), points.max(axis=0)
    return write_mat73(path, {"dataset": dataset, "minimalpos": lo.reshape(1, 3),
                              "maximalpos": hi.reshape(1, 3),
                              "sampling_grid_spacing": np.array([[0.01]])})


def write_znlos(path: Path, capture: Capture) -> Path:
    """A confocal capture whose time axis includes the device legs as a Zaragoza (ZNLOS)
    file: ``data`` (X, Y, bounces=1, T, colours=1), point grids stored as (3, Y, X)."""
    import h5py

    if capture.kind is not CaptureKind.CONFOCAL or capture.sensor_grid_format is not \
            GridFormat.X_Y_3:
        raise LayoutError("this ZNLOS writer holds confocal grids")
    if not capture.t_accounts_first_and_last_bounces:
        raise LayoutError("the ZNLOS layout counts the device legs")
    nx, ny = capture.grid_shape
    if nx != ny:
        raise LayoutError("the confocal ZNLOS layout holds square grids")
    assert capture.sensor_xyz is not None and capture.laser_xyz is not None
    data = np.transpose(capture.H, (1, 2, 0))[:, :, None, :, None]
    normals = (capture.sensor_grid_normals if capture.sensor_grid_normals is not None
               else np.broadcast_to([0.0, 0.0, 1.0], capture.sensor_grid_xyz.shape))
    with h5py.File(path, "w") as f:
        f["data"] = data.astype(np.float32)
        f["deltaT"] = np.float64(capture.delta_t)
        f["t0"] = np.float64(capture.t_start)
        f["cameraPosition"] = capture.sensor_xyz
        f["laserPosition"] = capture.laser_xyz
        for name in ("cameraGridPositions", "laserGridPositions"):
            f[name] = capture.sensor_grid_xyz.T
        for name in ("cameraGridNormals", "laserGridNormals"):
            f[name] = np.asarray(normals).T
    return path


# ---------------------------------------------------------------------- known samples
@dataclass(frozen=True)
class Sample:
    """A capture representable in one layout, and the writer of that layout."""

    scene: dict[str, Any]
    """The analytic scene (a :func:`~nlosfw.testing.fixtures.tiny_scene_config`)."""
    write: Callable[[Path, Capture], Path]
    """Writes the capture in the layout into a directory; returns the file to read."""


def _lct(folder: Path, capture: Capture) -> Path:
    return write_lct(folder / "data_sample.mat", capture)


def _fk(folder: Path, capture: Capture) -> Path:
    return write_fk(folder, capture)[0]


def _wisconsin(folder: Path, capture: Capture) -> Path:
    return write_wisconsin(folder / "sample.mat", capture)


def _znlos(folder: Path, capture: Capture) -> Path:
    return write_znlos(folder / "sample.hdf5", capture)


def _scene(**kwargs: Any) -> dict[str, Any]:
    from nlosfw.testing.fixtures import tiny_scene_config

    return tiny_scene_config(**kwargs)


def lct_scene(resolution: int = 8, bins: int = 1700) -> dict[str, Any]:
    """A tiny confocal scene in the LCT layout's terms (4 ps bins, 1 m square)."""
    return _scene(confocal=True, resolution=resolution, bins=bins,
                  bin_width=LCT_BIN_PS * 1e-12 * SPEED_OF_LIGHT)


def fk_scene(resolution: int = 8, bins: int = 330) -> dict[str, Any]:
    """A tiny confocal scene in the f-k layout's terms (32 ps bins, 2 m square)."""
    config = _scene(confocal=True, resolution=resolution, bins=bins,
                    bin_width=FK_BIN_PS * 1e-12 * SPEED_OF_LIGHT)
    config["wall"]["size"] = [2.0, 2.0]
    return config


def wisconsin_scene() -> dict[str, Any]:
    """A tiny single-spot scene with device legs."""
    config = _scene(device_legs=True, bins=400)
    config["capture"]["laser_position"] = [0.3, -0.2, 0.4]
    config["capture"]["sensor_position"] = [-0.6, 0.1, 0.3]
    return config


def znlos_scene() -> dict[str, Any]:
    """A tiny confocal scene with device legs."""
    config = _scene(confocal=True, device_legs=True, bins=400)
    config["capture"]["laser_position"] = [-0.6, 0.1, 0.3]
    config["capture"]["sensor_position"] = [-0.6, 0.1, 0.3]
    return config


#: The published layouts the kit can write, by the name of the format that reads them.
SAMPLES: dict[str, Sample] = {
    "lct": Sample(lct_scene(), _lct),
    "fk": Sample(fk_scene(), _fk),
    "wisconsin": Sample(wisconsin_scene(), _wisconsin),
    "znlos": Sample(znlos_scene(), _znlos),
}


def known_captures(spec: PluginSpec) -> list[Capture]:
    """Analytic captures the kit writes in ``spec``'s layout (several for a writable format:
    single spot and confocal, with device legs)."""
    from nlosfw.simulate.analytic import AnalyticSimulator
    from nlosfw.simulate.scene import scene_from_config
    from nlosfw.testing.fixtures import tiny_scene_config

    if C.WRITABLE in spec.capabilities:
        scenes = [tiny_scene_config(device_legs=True, bins=400),
                  tiny_scene_config(confocal=True)]
    elif spec.name in SAMPLES and spec.distribution == "nlosfw":
        scenes = [SAMPLES[spec.name].scene]
    else:
        raise unittest.SkipTest(f"{spec.qualified_name}: the kit cannot write a file in its "
                                "layout; declare the capability writable to be checked")
    return [AnalyticSimulator().simulate(scene_from_config(s)) for s in scenes]


def write_sample(spec: PluginSpec, fmt: CaptureFormat, capture: Capture, folder: Path) -> Path:
    """``capture`` in ``spec``'s layout, in ``folder`` (a name that says nothing of it)."""
    if C.WRITABLE in spec.capabilities:
        return fmt.write(folder / "sample.dat", capture)
    return SAMPLES[spec.name].write(folder, capture)

"""Wisconsin/Zaragoza phasor-field captures (Liu et al., "Non-line-of-sight imaging using
phasor-field virtual wave optics", Nature 572, 2019; Liu, Bauer, Velten, "Phasor field
diffraction based reconstruction for fast non-line-of-sight imaging systems", Nature
Communications 11, 2020), MATLAB v7.3 (HDF5) ``.mat`` files.

Published at https://biostat.wisc.edu/~compoptics/phasornlos20/fastnlos.html. The layout
is the one y-tal reads (``tal/io/format.py``, ``__convert_dict_pfmat_to_tal``, format
``MAT_PHASOR_FIELDS``; https://github.com/diegoroyo/tal), matched here field for field:

* a struct ``dataset`` with ``t`` (the number of bins), ``data`` of shape (nt, ns, nl) as
  h5py reads it (MATLAB ``[nl, ns, nt]``) with one camera point (``ns = 1``),
  ``laserOrigin``, ``laserPos`` (nl points), ``laserNorm``, ``cameraPos`` (the camera's
  point on the wall), ``cameraNormal``, ``deltat`` and ``t0`` (metres of optical path:
  the authors' conversion scripts multiply the gate times by c);
  top-level ``minimalpos``, ``maximalpos`` and ``sampling_grid_spacing`` (the volume).
* y-tal swaps laser and sensor by reciprocity: the capture's sensor points are the laser
  positions (``sensor_grid_xyz = laserPos``, ``sensor_xyz = laserOrigin``) and its one
  "laser" point is the camera's (``laser_grid_xyz = laser_xyz = cameraPos``);
  ``H_format`` T_Si, grids N_3 (points given as n x 3 or 3 x n), the time axis includes the
  device legs (``t_accounts_first_and_last_bounces`` true), ``t_start = t0``.
  Where y-tal stacks a single normal into shape (n, 1, 3), the normals here are (n, 3).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from nlosfw.capture.data import Capture
from nlosfw.capture.dataset_shapes import VOLUME_HINT
from nlosfw.capture.enums import GridFormat, HFormat, VolumeFormat
from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig
from nlosfw.capture.matfile import (
    hdf5_keys,
    hdf5_shape,
    is_hdf5,
    mat_struct_shapes,
    mat_variables,
    read_mat_array,
    read_mat_struct,
    scalar,
)
from nlosfw.common import hdf5_guard
from nlosfw.common.errors import DataError
from nlosfw.common.hdf5_guard import Expected, open_checked, ranks, values

#: The struct's fields that must be present.
FIELDS = ("t", "data", "laserOrigin", "laserPos", "cameraPos", "deltat", "t0")
_EXPECTED = ("a struct 'dataset' with t, data [nl, 1, nt], laserOrigin, laserPos, laserNorm, "
             "cameraPos, cameraNormal, deltat, t0, as in the Wisconsin phasor-field captures")


def struct_shapes(n_l: int) -> dict[str, Expected]:
    """The MATLAB shapes the fields of the struct ``dataset`` may declare, for ``n_l`` laser
    positions (the first axis of ``data``)."""
    one, point = values(1, what="one number"), values(3, what="3 numbers (one point)")
    return {"t": one, "deltat": one, "t0": one, "data": ranks(3, what="[nl, 1, nt]"),
            "laserOrigin": point, "cameraPos": point, "cameraNormal": point,
            "laserPos": hdf5_guard.points(n_l, what=f"{n_l} points n x 3 (or 3 x n), one "
                                                    "per row of data"),
            "laserNorm": hdf5_guard.points(1, n_l, what=f"one or {n_l} normals n x 3 (or "
                                                        "3 x n)")}


def points(value: npt.ArrayLike, path: Path, name: str, count: int | None = None) -> np.ndarray:
    """``value`` (MATLAB n x 3 or 3 x n) as (n, 3); one point repeated ``count`` times."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1 and arr.size == 3:
        arr = arr.reshape(1, 3)
    if arr.ndim != 2 or 3 not in arr.shape:
        raise DataError(f"{path}: field 'dataset.{name}' has shape {list(arr.shape)}; expected "
                        "points as n x 3 (or 3 x n)")
    n3 = arr if arr.shape[1] == 3 else arr.T
    if count is not None and n3.shape[0] == 1 and count > 1:
        n3 = np.repeat(n3, count, axis=0)
    if count is not None and n3.shape[0] != count:
        raise DataError(f"{path}: field 'dataset.{name}' holds {n3.shape[0]} points; expected "
                        f"{count}")
    return n3


class WisconsinFormat(CaptureFormat[CaptureFormatConfig]):
    """Wisconsin/Zaragoza phasor-field ``.mat`` captures (``MAT_PHASOR_FIELDS``); read only."""

    def detect(self, path: Path) -> bool:
        keys = hdf5_keys(path, "dataset")
        return keys is not None and {"data", "deltat"} <= keys

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        shape = hdf5_shape(path, "dataset/data")          # MATLAB [nl, 1, nt], reversed
        if shape is None or len(shape) != 3:
            return None
        n_t, _, n_l = shape
        return n_t, n_l, 1                  # the laser points are the sensor points

    def read(self, path: Path) -> Capture:
        if not is_hdf5(path):
            raise DataError(f"{path}: not a MATLAB 7.3 (HDF5) file; expected {_EXPECTED}")
        if hdf5_keys(path, "dataset") is None:
            with open_checked(path):   # says why when data lies outside the file, or damage
                pass
            raise DataError(f"{path}: no struct 'dataset' (expected {_EXPECTED})")
        declared = mat_struct_shapes(path, "dataset")
        missing = [k for k in FIELDS if k not in declared]
        if missing:
            raise DataError(f"{path}: no field 'dataset.{missing[0]}' (expected {_EXPECTED})")
        data_shape = declared["data"]
        if len(data_shape) != 3 or data_shape[1] != 1:
            raise DataError(f"{path}: field 'dataset.data' has MATLAB shape {list(data_shape)}; "
                            "expected [nl, 1, nt] (one camera point)")
        ds = read_mat_struct(path, "dataset", (*FIELDS, "laserNorm", "cameraNormal"),
                             struct_shapes(data_shape[0]))
        data = np.asarray(ds["data"])
        n_l, _, n_t = data.shape
        n_t_declared = int(scalar(ds["t"], path, "dataset.t", "the number of time bins"))
        if n_t_declared != n_t:
            raise DataError(f"{path}: field 'dataset.t' says {n_t_declared} bins but "
                            f"'dataset.data' has {n_t}")
        if not np.issubdtype(data.dtype, np.number) or not np.all(np.isfinite(data)):
            raise DataError(f"{path}: field 'dataset.data' must hold finite numbers")
        H = np.ascontiguousarray(data[:, 0, :].T, dtype=np.float32)
        camera = points(ds["cameraPos"], path, "cameraPos", 1)
        normals = (points(ds["laserNorm"], path, "laserNorm", n_l) if "laserNorm" in ds
                   else None)
        camera_normal = (points(ds["cameraNormal"], path, "cameraNormal", 1)
                         if "cameraNormal" in ds else None)
        volume = {}
        present = mat_variables(path)
        for src, dst in (("minimalpos", "minimal_pos"), ("maximalpos", "maximal_pos"),
                         ("sampling_grid_spacing", "sampling_grid_spacing")):
            if src not in present:
                continue
            value = np.asarray(read_mat_array(path, src, expected=VOLUME_HINT),
                               dtype=float).reshape(-1)
            volume[dst] = float(value[0]) if value.size == 1 else value.tolist()
        try:
            return Capture(
                H=H, H_format=HFormat.T_Si,
                sensor_xyz=points(ds["laserOrigin"], path, "laserOrigin", 1).reshape(3),
                sensor_grid_xyz=points(ds["laserPos"], path, "laserPos", n_l),
                sensor_grid_normals=normals, sensor_grid_format=GridFormat.N_3,
                laser_xyz=camera.reshape(3), laser_grid_xyz=camera,
                laser_grid_normals=camera_normal, laser_grid_format=GridFormat.N_3,
                volume_format=VolumeFormat.X_Y_Z_3,
                delta_t=scalar(ds["deltat"], path, "dataset.deltat", "one number of metres"),
                t_start=scalar(ds["t0"], path, "dataset.t0", "one number of metres"),
                t_accounts_first_and_last_bounces=True,
                scene_info={"original_format": "MAT_PHASOR_FIELDS", "volume": volume})
        except DataError as err:
            raise DataError(f"{path}: {err}") from None

"""Stanford f-k captures (Lindell, Wetzstein, O'Toole, "Wave-based non-line-of-sight
imaging using fast f-k migration", ACM Trans. Graph. 38(4), 2019), MATLAB v7.3 files.

Published at http://www.computationalimaging.org/publications/nlos-fk/ with code at
https://github.com/computational-imaging/nlos-fk. Facts used here, from that
repository's README, ``demo.m`` and ``cnlos_reconstruction.m``:

* ``meas_<minutes>min.mat`` holds ``meas``, "a 3D variable ... of dimension 512x512x2048,
  with time being the last dimension"; "the time resolution of the measurements is
  32 ps" (``bin_resolution = 32e-12``), so ``delta_t`` = 32 ps x c of optical path.
  These are MATLAB v7.3 files, i.e. HDF5 (read with h5py, axes reversed back to
  MATLAB's order); a v5 file with the same variables is read as well.
* the scanned area is "2 m x 2 m" (``wall_size = 2; width = wall_size / 2``); the points
  are taken cell-centred, 2 m / N apart (the spacing the code's f-k migration assumes).
* ``tof.mat`` beside the measurements holds ``tofgrid``, "the time of flight in
  picoseconds to each scan point", used to "'rectify' the measurements such that time
  zero coincides with the moment the light reflects off of the wall": each histogram is
  shifted left by ``floor(tofgrid / 32)`` bins (``circshift(meas(ii,jj,:), ... -floor(
  tofgrid(ii,jj) / (bin_resolution*1e12)))``; nlosfw shifts zeros in at the end instead
  of wrapping the first bins around). After it ``t_start`` = 0 and the time axis holds no
  device legs. This format's default is ``capture.tofgrid = <the file's folder>/tof.mat``
  when that file exists (``capture.tofgrid=''`` turns it off).
* the code then keeps 512 bins (``crop = 512``, "bin index to crop measurements after
  aligning so that direct component is at t=0"): the default ``capture.time_crop.bins =
  [0, 512]``. The sensor was gated so the direct reflection is not recorded: no gate.
* axes: ``demo.m`` marks ``meas`` as ``% y, x, t``; the code's front view (``imagesc`` of
  the volume after ``permute(vol, [1 3 2])``, ``flip(vol, 2)``, ``flip(vol, 3)`` with
  ``tic_x = tic_y = linspace(width, -width)``) shows ``meas(i, j)`` with i top to bottom
  and j left to right. nlosfw maps them so that its figures (x to the right, y up) show
  the same view: x grows with the second MATLAB axis, y decreases along the first.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.dataset_shapes import SQUARE_SCAN
from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.capture.matfile import (
    read_mat_array,
    require_variables,
    scan_shape,
    variables_or_none,
)
from nlosfw.capture.preprocess import Preprocessing, TimeCrop
from nlosfw.capture.scan import ConfocalScan, ScanLayout, confocal_capture
from nlosfw.common.errors import DataError
from nlosfw.common.hdf5_guard import ranks

log = logging.getLogger(__name__)

#: Bin width of the published captures (s).
BIN_SECONDS = 32e-12
#: Half the side of the scanned square (m): the 2 m x 2 m wall.
HALF_WIDTH = 1.0
#: Bins the authors' code keeps after removing the per-pixel delays.
CROP_BINS = 512
#: The per-pixel delay file beside the measurements, and its variable.
TOF_FILE, TOF_VARIABLE = "tof.mat", "tofgrid"
#: The largest per-pixel delay accepted (ps): 1 microsecond, 300 m of light path.
MAX_DELAY_PS = 1e6
#: ``meas[i, j, t]``: x grows with j, y decreases with i (see the module docstring).
LAYOUT = ScanLayout(x_axis=1, x_reversed=False, y_reversed=True)
_EXPECTED = ("meas, the histograms [N, N, T] (32 ps bins) of a confocal scan of a 2 m x 2 m "
             "wall, as in the Stanford f-k captures")


class FkFormat(CaptureFormat[CaptureFormatConfig]):
    """Stanford f-k ``.mat`` captures (``meas``, per-pixel delays in ``tof.mat``); read only."""

    def detect(self, path: Path) -> bool:
        found = variables_or_none(path) or {}
        meas = found.get("meas")
        return meas is not None and len(meas.shape) == 3 and "rect_data" not in found

    def read(self, path: Path) -> Capture:
        found = require_variables(path, ("meas",), _EXPECTED)
        shape = found["meas"].shape
        if len(shape) != 3 or shape[0] != shape[1]:
            extra = " (a sequence of scans: save one frame as meas)" if len(shape) == 4 else ""
            raise DataError(f"{path}: variable 'meas' has shape {list(shape)}; expected one "
                            f"square scan [N, N, T]{extra}")
        meas = read_mat_array(path, "meas", dtype=np.float32, expected=SQUARE_SCAN)
        if not np.all(np.isfinite(meas)):
            raise DataError(f"{path}: variable 'meas' contains NaN or inf")
        scan = ConfocalScan(histograms=meas, layout=LAYOUT, half_width=HALF_WIDTH,
                            delta_t=BIN_SECONDS * SPEED_OF_LIGHT,
                            scene_info={"original_format": "MAT_FK", "bin_seconds": BIN_SECONDS})
        try:
            return confocal_capture(scan)
        except DataError as err:
            raise DataError(f"{path}: variable 'meas': {err}") from None

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        return scan_shape(path, "meas")

    def defaults(self, path: Path) -> Preprocessing:
        tof = path.parent / TOF_FILE
        if not tof.is_file():
            log.warning("%s: no %s beside it: the per-pixel delays are not removed and the time "
                        "axis does not start at the wall; give capture.tofgrid=<file>", path,
                        TOF_FILE)
        found = (variables_or_none(path) or {}).get("meas")
        n_bins = found.shape[-1] if found is not None and found.shape else 0
        return Preprocessing(tofgrid=str(tof) if tof.is_file() else None,
                             time_crop=TimeCrop(bins=(0, CROP_BINS)) if n_bins > CROP_BINS
                             else TimeCrop())


def tofgrid_shape(path: Path) -> tuple[int, ...] | None:
    """The MATLAB shape ``tofgrid`` declares in a ``tof.mat`` (None: the file has no such
    variable, or is no MATLAB file); from its header, nothing read."""
    found = (variables_or_none(path) or {}).get(TOF_VARIABLE)
    return None if found is None else found.shape


def read_tofgrid(path: Path) -> np.ndarray:
    """The per-pixel delays (ps) of a ``tof.mat`` (v5 or v7.3), in MATLAB's ``[i, j]`` order."""
    require_variables(path, (TOF_VARIABLE,), "tofgrid, the per-pixel delays in picoseconds "
                                             "[N, N] of the scan")
    delays = read_mat_array(path, TOF_VARIABLE, dtype=np.float64, expected=ranks(
        2, what="[N, N] (one delay in picoseconds per scan point)"))
    if not np.all(np.isfinite(delays)):
        raise DataError(f"{path}: variable '{TOF_VARIABLE}' contains NaN or inf")
    low, high = float(delays.min()), float(delays.max())
    if low < 0 or high > MAX_DELAY_PS:
        raise DataError(f"{path}: variable '{TOF_VARIABLE}' holds delays from {low:g} to "
                        f"{high:g} ps; expected times of flight from 0 to {MAX_DELAY_PS:g} ps")
    return delays

"""Stanford LCT captures (O'Toole, Lindell, Wetzstein, "Confocal non-line-of-sight imaging
based on the light-cone transform", Nature 555, 2018), MATLAB v5 ``.mat`` files.

Published with the authors' MATLAB code ("LCT MATLAB code and data") at
https://www.computationalimaging.org/publications/confocal-non-line-of-sight-imaging-based-on-the-light-cone-transform/
(scenes ``data_resolution_chart_40cm.mat``, ``data_s_u.mat``, ``data_outdoor_s.mat``, ...).
Facts used here, each from the authors' ``cnlos_reconstruction.m`` of that release:

* ``rect_data``: the histograms, uint16 ``[N, N, T]`` (64 x 64 x 2048, some scenes
  32 x 32 x 4096): a confocal raster scan, time last. ``N = size(rect_data, 1)``,
  ``M = size(rect_data, 3)``.
* bins of 4 ps (``bin_resolution = 4e-12; % Native bin resolution for SPAD is 4 ps``);
  ``range = M * c * bin_resolution`` is the optical path the histogram spans, so the
  time axis is the round trip wall -> hidden point -> wall: ``delta_t`` = 4 ps x c.
* time zero at the wall: the files are "pre-rectified (i.e., direct component starts at
  the first time bin)"; no device legs in the time axis; ``t_start`` = 0.
* ``width``: a 1 x 1 double, half the side of the scanned square in metres (the volume's
  axes are ``linspace(-width, width, N)``, and the light-cone kernel's slope is
  ``width / range`` on a grid whose unit is the scan's full side 2 ``width``); the scan
  points are taken cell-centred, 2 ``width`` / N apart (the spacing the kernel assumes).
* the direct reflection and its tail fill the first bins: the code zeroes them for every
  scene, ``z_trim = 600; % Set first 600 bins to zero`` then ``rect_data(:,:,1:z_trim) = 0``
  (halving ``z_trim`` with each halving of the bins, so always the first 600 x 4 ps =
  2.4 ns, 0.72 m of path). This format's default preprocessing is that gate:
  ``capture.gate.bins = 600`` (``capture.gate.bins=0`` turns it off).
* axes: the code reconstructs ``permute(rect_data, [3 2 1])`` with the volume's second
  axis along ``tic_y = linspace(-width, width)`` and its third along ``tic_x``, flips the
  x axis "for visualization" (``vol = vol(:,:,end:-1:1)``) and shows the front view with
  ``imagesc`` (first row at the top). In that front view the first MATLAB axis of
  ``rect_data`` runs right to left and the second top to bottom. nlosfw maps them so that
  its figures (x to the right, y up) show the scene as the authors' front view does:
  x decreases along the first axis and y along the second. ``capture.flip`` and
  ``capture.transpose`` change this for a file that follows another convention.
* per scene (``isdiffuse``, ``snr``, ``z_offset``): the authors set them by hand for each
  scene; nlosfw attaches none (a capture's name says nothing to the reader): the transient
  imagers estimate their falloff and Wiener SNR from the data
  (:mod:`nlosfw.image.data_settings`) unless their options set them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.dataset_shapes import SQUARE_SCAN
from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.capture.matfile import (
    read_mat_array,
    require_variables,
    scalar,
    scan_shape,
    variables_or_none,
)
from nlosfw.capture.preprocess import Gate, Preprocessing
from nlosfw.capture.scan import ConfocalScan, ScanLayout, confocal_capture
from nlosfw.common.errors import DataError
from nlosfw.common.hdf5_guard import values

#: Bin width of the published captures (s).
BIN_SECONDS = 4e-12
#: Leading bins the authors' code zeroes in every scene (the direct reflection).
DIRECT_REFLECTION_BINS = 600
#: The half-widths (m) accepted: a millimetre to a kilometre (outside: a unit mistake).
MIN_WIDTH, MAX_WIDTH = 1e-3, 1e3
#: ``rect_data[i, j, t]``: x decreases with i, y decreases with j (see the module docstring).
LAYOUT = ScanLayout(x_axis=0, x_reversed=True, y_reversed=True)
_EXPECTED = ("rect_data, the histograms [N, N, T] (uint16, 4 ps bins), and width, half the "
             "side of the scanned square in metres, as in the Stanford LCT captures")


class LctFormat(CaptureFormat[CaptureFormatConfig]):
    """Stanford LCT ``.mat`` captures (``rect_data`` and ``width``); read only."""

    def detect(self, path: Path) -> bool:
        found = variables_or_none(path) or {}
        data = found.get("rect_data")
        return data is not None and len(data.shape) == 3 and "width" in found

    def read(self, path: Path) -> Capture:
        found = require_variables(path, ("rect_data", "width"), _EXPECTED)
        if len(found["rect_data"].shape) != 3:
            raise DataError(f"{path}: variable 'rect_data' has shape "
                            f"{list(found['rect_data'].shape)}; expected [N, N, T]")
        width = scalar(read_mat_array(path, "width", expected=values(1, what="one number")),
                       path, "width", "one number of metres (half the side of the scanned "
                       "square)")
        if width <= 0:
            raise DataError(f"{path}: variable 'width' is {width}; expected a positive number of "
                            "metres (half the side of the scanned square)")
        if not MIN_WIDTH <= width <= MAX_WIDTH:
            raise DataError(f"{path}: variable 'width' is {width:g}; expected half the side of "
                            f"the scanned square, {MIN_WIDTH:g} to {MAX_WIDTH:g} metres")
        rect_data = read_mat_array(path, "rect_data", expected=SQUARE_SCAN)
        if rect_data.ndim != 3 or rect_data.shape[0] != rect_data.shape[1]:
            raise DataError(f"{path}: variable 'rect_data' has shape {list(rect_data.shape)}; "
                            "expected a square scan [N, N, T]")
        if not np.all(np.isfinite(rect_data)):
            raise DataError(f"{path}: variable 'rect_data' contains NaN or inf")
        scan = ConfocalScan(histograms=rect_data, layout=LAYOUT, half_width=width,
                            delta_t=BIN_SECONDS * SPEED_OF_LIGHT,
                            scene_info={"original_format": "MAT_LCT", "width": width,
                                        "bin_seconds": BIN_SECONDS})
        try:
            return confocal_capture(scan)
        except DataError as err:
            raise DataError(f"{path}: variable 'rect_data': {err}") from None

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        return scan_shape(path, "rect_data")

    def defaults(self, path: Path) -> Preprocessing:
        return Preprocessing(gate=Gate(bins=DIRECT_REFLECTION_BINS))

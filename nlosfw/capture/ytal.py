"""y-tal's HDF5 capture files, and nlosfw's own (the same layout with two root attributes).

``ytal`` and ``nlosfw`` are one reader under two names: both read y-tal's layout
(:mod:`nlosfw.capture.hdf5`; y-tal: https://github.com/diegoroyo/tal, ``tal.io``). They
differ in what they claim and write: ``nlosfw`` files carry the root attribute
``nlosfw_type = "capture"`` (written by nlosfw: run directories, the cache), ``ytal``
files are every other file with y-tal's datasets ``H`` and ``H_format`` (written by y-tal
or any other tool). ``ytal`` writes exactly what y-tal writes; ``nlosfw`` adds the
attributes. Either reads the other's files when forced.
"""

from __future__ import annotations

import math
from pathlib import Path

from nlosfw.capture.data import Capture
from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig
from nlosfw.capture.hdf5 import (
    NLOSFW_CAPTURE_TYPE,
    capture_from_fields,
    read_fields,
    write_capture,
)
from nlosfw.capture.matfile import hdf5_keys, hdf5_shape
from nlosfw.common.errors import DataError
from nlosfw.common.reading import hdf5_file


def _nlosfw_type(path: Path) -> str | None:
    """The ``nlosfw_type`` root attribute of a y-tal HDF5 file (None: not y-tal's layout)."""
    keys = hdf5_keys(path)
    if keys is None or not {"H", "H_format"} <= keys:
        return None
    try:
        with hdf5_file(path) as f:
            found = f.attrs.get("nlosfw_type", "")
    except OSError:
        return None
    return found.decode() if isinstance(found, bytes) else str(found)


class YtalFormat(CaptureFormat[CaptureFormatConfig]):
    """y-tal HDF5 captures (``tal.io.write_capture``); reads and writes."""

    def detect(self, path: Path) -> bool:
        found = _nlosfw_type(path)
        return found is not None and found != NLOSFW_CAPTURE_TYPE

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        shape = hdf5_shape(path, "H")        # time first; (T, Lx, Ly, Sx, Sy) if exhaustive
        if not shape:
            return None
        if len(shape) == 5:
            return shape[0], shape[3] * shape[4], shape[1] * shape[2]
        return shape[0], math.prod(shape[1:]), 1

    def read(self, path: Path) -> Capture:
        raw = read_fields(path)
        if "H" not in raw and "data" in raw:
            raise DataError(f"{path}: no field 'H' (a y-tal capture needs H, H_format, "
                            "sensor_grid_xyz, laser_grid_xyz, delta_t); this looks like a "
                            "Zaragoza (znlos) file")
        return capture_from_fields(raw, path)

    def write(self, path: Path, capture: Capture) -> Path:
        return write_capture(path, capture, nlosfw_attributes=False)


class NlosfwFormat(YtalFormat):
    """nlosfw's captures: y-tal's layout plus the root attribute ``nlosfw_type``."""

    def detect(self, path: Path) -> bool:
        return _nlosfw_type(path) == NLOSFW_CAPTURE_TYPE

    def write(self, path: Path, capture: Capture) -> Path:
        return write_capture(path, capture)

"""The Zaragoza NLOS dataset's HDF5 files (ZNLOS, Galindo et al. 2019), read as y-tal does.

Layout (from y-tal's ``tal/io/format.py``, ``__convert_dict_znlos_to_tal``): top-level
datasets ``data`` (7 axes for exhaustive captures, 5 for confocal ones, in either of two
axis orders; the colour and bounce axes are summed), ``deltaT`` and ``t0`` (metres of
optical path), ``cameraPosition``, ``cameraGridPositions``, ``cameraGridNormals``,
``laserPosition``, ``laserGridPositions``, ``laserGridNormals`` (point grids stored as
(3, ...) and transposed), and the hidden volume ``hiddenVolumePosition``,
``hiddenVolumeRotation``, ``hiddenVolumeSize``. Its time axis includes the device legs.
Published at https://graphics.unizar.es/nlos_dataset.html.
"""

from __future__ import annotations

from pathlib import Path

from nlosfw.capture.data import Capture
from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig
from nlosfw.capture.hdf5 import capture_from_fields, read_fields
from nlosfw.capture.matfile import hdf5_keys, hdf5_shape
from nlosfw.capture.znlos_layout import data_transient_shape, znlos_to_ytal
from nlosfw.common.errors import DataError

#: The datasets that identify a ZNLOS file.
SIGNATURE = ("data", "deltaT", "t0", "cameraGridPositions")


class ZnlosFormat(CaptureFormat[CaptureFormatConfig]):
    """Zaragoza NLOS dataset (HDF5_ZNLOS) files; read only."""

    def detect(self, path: Path) -> bool:
        keys = hdf5_keys(path)
        return keys is not None and set(SIGNATURE) <= keys and "H" not in keys

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        shape = hdf5_shape(path, "data")
        return None if shape is None else data_transient_shape(shape)

    def read(self, path: Path) -> Capture:
        raw = read_fields(path)
        if "H" in raw:
            raise DataError(f"{path}: holds a y-tal capture ('H'), not a Zaragoza (ZNLOS) file")
        return capture_from_fields(znlos_to_ytal(raw, path), path)

"""Stage 1, the capture: the transient measurement, its geometry, its HDF5 formats.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from nlosfw.capture.data import YTAL_FIELDS, Capture
from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat, VolumeFormat
from nlosfw.capture.geometry import SPEED_OF_LIGHT, CaptureGeometry, device_legs
from nlosfw.capture.hdf5 import read_capture, write_capture

__all__ = [
    "Capture",
    "CaptureGeometry",
    "CaptureKind",
    "device_legs",
    "GridFormat",
    "HFormat",
    "read_capture",
    "SPEED_OF_LIGHT",
    "VolumeFormat",
    "write_capture",
    "YTAL_FIELDS",
]

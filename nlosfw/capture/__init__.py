"""Stage 1, the capture: the transient measurement, its geometry, its file formats, and
its preprocessing.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.capture.data import YTAL_FIELDS, Capture
    from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat, VolumeFormat
    from nlosfw.capture.formats import CaptureFormat, CaptureFormatConfig, detect_format, read_with
    from nlosfw.capture.geometry import SPEED_OF_LIGHT, CaptureGeometry, device_legs
    from nlosfw.capture.hdf5 import read_capture, write_capture
    from nlosfw.capture.matfile import mat_variables, read_mat_array, read_mat_struct
    from nlosfw.capture.pileup import (
        coates_rates,
        correct_pileup,
        first_photon_probabilities,
        piled_up_counts,
    )
    from nlosfw.capture.preprocess import (
        AppliedStep,
        BinWidth,
        Extras,
        FlipAxes,
        Gate,
        Preprocessing,
        TimeCrop,
        preprocess,
    )
    from nlosfw.capture.scan import ConfocalScan, ScanLayout, confocal_capture, square_scan_grid

__all__ = [
    "AppliedStep",
    "BinWidth",
    "Capture",
    "CaptureFormat",
    "CaptureFormatConfig",
    "coates_rates",
    "correct_pileup",
    "first_photon_probabilities",
    "piled_up_counts",
    "ConfocalScan",
    "confocal_capture",
    "detect_format",
    "Extras",
    "FlipAxes",
    "Gate",
    "mat_variables",
    "Preprocessing",
    "preprocess",
    "read_mat_array",
    "read_mat_struct",
    "read_with",
    "ScanLayout",
    "square_scan_grid",
    "TimeCrop",
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
__getattr__, __dir__ = lazy_exports(__name__, __file__)

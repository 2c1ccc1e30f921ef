"""Reading and writing captures (y-tal's HDF5 layout), phasor fields and reconstructions."""

from nlosfw.io.atomic import atomic_path, write_text
from nlosfw.io.capture_hdf5 import read_capture, write_capture
from nlosfw.io.field_hdf5 import (
    read_phasor_field,
    read_reconstruction,
    write_phasor_field,
    write_reconstruction,
)

__all__ = [
    "atomic_path", "read_capture", "read_phasor_field", "read_reconstruction", "write_capture",
    "write_phasor_field", "write_reconstruction", "write_text",
]

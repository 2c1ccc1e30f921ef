"""Phasor fields as HDF5 files (nlosfw's own layout, ``nlosfw_type`` ``PhasorField``)."""

from __future__ import annotations

from pathlib import Path

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import DataError
from nlosfw.common.hdf5 import (
    new_file,
    open_typed,
    read_dataset,
    read_yaml,
    write_header,
    write_yaml,
)
from nlosfw.transform.field import PhasorField


def write_phasor_field(path: str | Path, field: PhasorField, overwrite: bool = False) -> Path:
    """Write ``field`` atomically; an existing file is kept unless ``overwrite``."""
    with new_file(path, overwrite=overwrite) as f:
        write_header(f, "PhasorField")
        f.create_dataset("values", data=field.values)
        f.create_dataset("frequencies", data=field.frequencies)
        f.create_dataset("wall_xyz", data=field.wall_xyz)
        if field.weights is not None:
            f.create_dataset("weights", data=field.weights)
        write_yaml(f, "geometry", field.geometry.to_dict())
        write_yaml(f, "metadata", field.metadata)
    return Path(path)


def read_phasor_field(path: str | Path) -> PhasorField:
    """Read a file written by :func:`write_phasor_field`."""
    with open_typed(path, "PhasorField") as (f, p):
        values = read_dataset(f, "values", p)
        freqs = read_dataset(f, "frequencies", p)
        wall = read_dataset(f, "wall_xyz", p)
        weights = read_dataset(f, "weights", p) if "weights" in f else None
        try:
            geometry = CaptureGeometry.from_dict(read_yaml(f, "geometry", p))
        except DataError as err:
            raise DataError(f"{p}: {err}") from None
        metadata = read_yaml(f, "metadata", p)
    try:
        return PhasorField(values=values, frequencies=freqs, wall_xyz=wall, geometry=geometry,
                           weights=weights, metadata=metadata)
    except DataError as err:
        raise DataError(f"{p}: {err}") from None

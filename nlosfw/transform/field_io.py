"""Phasor fields as HDF5 files (nlosfw's own layout, ``nlosfw_type`` ``PhasorField``).

The field's typed attributes (``band``, ``imaging_hints``, ``zero_filled``,
``depth_range``) are one YAML mapping, ``attributes``; a file written before they were
typed holds them in ``metadata``, which the field reads them out of."""

from __future__ import annotations

from pathlib import Path

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.capture.hints import ImagingHints
from nlosfw.common.errors import DataError
from nlosfw.common.hdf5 import (
    new_file,
    open_typed,
    read_dataset,
    read_yaml,
    write_header,
    write_yaml,
)
from nlosfw.transform.field import Band, PhasorField, depth_range_of


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
        attributes = _attributes(field)
        if attributes:
            write_yaml(f, "attributes", attributes)
    return Path(path)


def _attributes(field: PhasorField) -> dict[str, object]:
    """The field's typed attributes that are set, as plain values."""
    found: dict[str, object] = {}
    if field.band is not None:
        found["band"] = field.band.to_dict()
    if field.imaging_hints is not None:
        found["imaging_hints"] = field.imaging_hints.to_dict()
    if field.zero_filled:
        found["zero_filled"] = True
    if field.depth_range is not None:
        found["depth_range"] = [float(v) for v in field.depth_range]
    return found


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
        attributes = read_yaml(f, "attributes", p)
    if not isinstance(attributes, dict):
        raise DataError(f"{p}: field 'attributes' must be a YAML mapping")
    hints = attributes.get("imaging_hints")
    try:
        return PhasorField(values=values, frequencies=freqs, wall_xyz=wall, geometry=geometry,
                           weights=weights, metadata=metadata,
                           band=Band.from_mapping(attributes.get("band")),
                           imaging_hints=None if hints is None
                           else ImagingHints.from_mapping(hints),
                           zero_filled=attributes.get("zero_filled") is True,
                           depth_range=depth_range_of(attributes.get("depth_range")))
    except DataError as err:
        raise DataError(f"{p}: {err}") from None

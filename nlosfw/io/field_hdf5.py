"""Phasor fields and reconstructions as HDF5 files (nlosfw's own layout).

Both files carry the attribute ``nlosfw_type`` (``PhasorField`` or
``Reconstruction``) and ``format_version``; metadata is a YAML string.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from nlosfw.capture import CaptureGeometry
from nlosfw.errors import DataError
from nlosfw.io import yaml_safe
from nlosfw.io.atomic import atomic_path
from nlosfw.phasor_field import PhasorField
from nlosfw.reconstruction import Reconstruction

FORMAT_VERSION = 1


def write_phasor_field(path: str | Path, field: PhasorField, overwrite: bool = False) -> Path:
    """Write ``field`` atomically; an existing file is kept unless ``overwrite``."""
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        _header(f, "PhasorField")
        f.create_dataset("values", data=field.values)
        f.create_dataset("frequencies", data=field.frequencies)
        f.create_dataset("wall_xyz", data=field.wall_xyz)
        if field.weights is not None:
            f.create_dataset("weights", data=field.weights)
        _yaml(f, "geometry", field.geometry.to_dict())
        _yaml(f, "metadata", field.metadata)
    return Path(path)


def read_phasor_field(path: str | Path) -> PhasorField:
    """Read a file written by :func:`write_phasor_field`."""
    with _open(path, "PhasorField") as (f, p):
        values = _dataset(f, "values", p)
        freqs = _dataset(f, "frequencies", p)
        wall = _dataset(f, "wall_xyz", p)
        weights = _dataset(f, "weights", p) if "weights" in f else None
        geometry = CaptureGeometry.from_dict(_read_yaml(f, "geometry", p))
        metadata = _read_yaml(f, "metadata", p)
    try:
        return PhasorField(values=values, frequencies=freqs, wall_xyz=wall, geometry=geometry,
                           weights=weights, metadata=metadata)
    except DataError as err:
        raise DataError(f"{p}: {err}") from None


def write_reconstruction(path: str | Path, recon: Reconstruction,
                         overwrite: bool = False) -> Path:
    """Write ``recon`` atomically; an existing file is kept unless ``overwrite``."""
    with atomic_path(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        _header(f, "Reconstruction")
        f.create_dataset("intensity", data=recon.intensity)
        f.create_dataset("voxels", data=recon.voxels)
        _yaml(f, "metadata", recon.metadata)
    return Path(path)


def read_reconstruction(path: str | Path) -> Reconstruction:
    """Read a file written by :func:`write_reconstruction`."""
    with _open(path, "Reconstruction") as (f, p):
        intensity = _dataset(f, "intensity", p)
        voxels = _dataset(f, "voxels", p)
        metadata = _read_yaml(f, "metadata", p)
    try:
        return Reconstruction(intensity=intensity, voxels=voxels, metadata=metadata)
    except DataError as err:
        raise DataError(f"{p}: {err}") from None


def _header(f: h5py.File, kind: str) -> None:
    f.attrs["nlosfw_type"] = kind
    f.attrs["format_version"] = FORMAT_VERSION


def _yaml(f: h5py.File, key: str, value: Any) -> None:
    f.create_dataset(key, data=yaml_safe.dump(value), dtype=h5py.string_dtype("utf-8"))


class _open:
    """Open an nlosfw HDF5 file of the expected type, turning h5py errors into DataError."""

    def __init__(self, path: str | Path, kind: str) -> None:
        self.path, self.kind = Path(path), kind

    def __enter__(self) -> tuple[h5py.File, Path]:
        if not self.path.is_file():
            raise DataError(f"{self.path}: file not found")
        try:
            self.file = h5py.File(self.path, "r")
        except OSError as err:
            raise DataError(f"{self.path}: not a readable HDF5 file ({err})") from None
        found = self.file.attrs.get("nlosfw_type")
        if isinstance(found, bytes):
            found = found.decode()
        if found != self.kind:
            self.file.close()
            raise DataError(f"{self.path}: holds {found or 'no nlosfw data'}, expected a "
                            f"{self.kind} file")
        return self.file, self.path

    def __exit__(self, *exc: object) -> None:
        self.file.close()


def _dataset(f: h5py.File, key: str, path: Path) -> np.ndarray:
    if key not in f:
        raise DataError(f"{path}: missing field '{key}'")
    try:
        return f[key][()]
    except (OSError, RuntimeError) as err:
        raise DataError(f"{path}: field '{key}' cannot be read ({err})") from None


def _read_yaml(f: h5py.File, key: str, path: Path) -> dict:
    if key not in f:
        return {}
    raw = _dataset(f, key, path)
    try:
        value = yaml_safe.load(raw)
    except Exception as err:  # yaml errors
        raise DataError(f"{path}: field '{key}' is not valid YAML ({err})") from None
    return value or {}

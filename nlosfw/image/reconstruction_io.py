"""Reconstructions as HDF5 files (nlosfw's own layout, ``nlosfw_type`` ``Reconstruction``)."""

from __future__ import annotations

from pathlib import Path

from nlosfw.common.errors import DataError
from nlosfw.common.hdf5 import (
    new_file,
    open_typed,
    read_dataset,
    read_yaml,
    write_header,
    write_yaml,
)
from nlosfw.image.reconstruction import Reconstruction


def write_reconstruction(path: str | Path, recon: Reconstruction,
                         overwrite: bool = False) -> Path:
    """Write ``recon`` atomically; an existing file is kept unless ``overwrite``."""
    with new_file(path, overwrite=overwrite) as f:
        write_header(f, "Reconstruction")
        f.create_dataset("intensity", data=recon.intensity)
        f.create_dataset("voxels", data=recon.voxels)
        write_yaml(f, "metadata", recon.metadata)
    return Path(path)


def read_reconstruction(path: str | Path) -> Reconstruction:
    """Read a file written by :func:`write_reconstruction`."""
    with open_typed(path, "Reconstruction") as (f, p):
        intensity = read_dataset(f, "intensity", p)
        voxels = read_dataset(f, "voxels", p)
        metadata = read_yaml(f, "metadata", p)
    try:
        return Reconstruction(intensity=intensity, voxels=voxels, metadata=metadata)
    except DataError as err:
        raise DataError(f"{p}: {err}") from None

"""The scene operator's constants stacked over voxel planes, which the neural hidden
volume's backends (:mod:`nlosfw.model.hybrid.volume`) write the operator from, and their
size, known before they are built."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.model.physics.operator import SceneOperator


@dataclass(frozen=True, eq=False)
class PlaneStack:
    """The operator's constants for a backend: per plane i and frequency f the kernel
    spectra K (Z, F, Ly, Lx), the laser legs L (Z, F, Y, X) (None: confocal), and where
    inputs are placed and outputs read on the padded (Ly, Lx) lattice. Forward:
    read(ifft2(sum_i K_i * fft2(place(a_i * L_i)))) (see
    :class:`~nlosfw.image.plane_convolution.PlaneConvolution`)."""

    spectra: np.ndarray
    laser: np.ndarray | None
    shape: tuple[int, int]
    inputs: tuple[slice, slice]
    outputs: tuple[slice, slice]


ALIGNMENT = 64
"""Byte alignment of :func:`plane_stack`'s arrays (JAX uses a CPU array in place only when
it is 64-byte aligned, and copies it otherwise)."""


def aligned_empty(shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
    """An uninitialised C-contiguous array whose data starts on a :data:`ALIGNMENT`-byte
    boundary."""
    dt = np.dtype(dtype)
    size = math.prod(shape) * dt.itemsize
    raw = np.empty(size + ALIGNMENT, np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    return raw[start:start + size].view(dt).reshape(shape)


def plane_stack(op: SceneOperator) -> PlaneStack:
    """The constants of ``op`` (its dtype) stacked over planes, each written into its place
    (the memory held is :func:`stack_bytes`, not twice that), in :func:`aligned_empty`
    arrays."""
    z = op.lattice.depths.size
    spectra: np.ndarray | None = None
    laser: np.ndarray | None = None
    for i in range(z):
        plane = op.kernel_spectra(i)
        if spectra is None:
            spectra = aligned_empty((z, *plane.shape), plane.dtype)
        spectra[i] = plane
        leg = None if op.confocal else op.laser_leg(i)
        if leg is not None:
            if laser is None:
                laser = aligned_empty((z, *leg.shape), leg.dtype)
            laser[i] = leg
    if spectra is None:
        raise DataError(f"{op.lattice}: no voxel plane to propagate")
    return PlaneStack(spectra, laser, op.conv.shape, op.conv.input_region,
                      op.conv.output_region)


def stack_bytes(op: SceneOperator) -> int:
    """Bytes of :func:`plane_stack`'s arrays for ``op`` (:func:`stack_size`, in the
    operator's dtype); nothing is computed."""
    return stack_size(op.lattice.depths.size, op.frequencies.size, op.conv.shape,
                      op.lattice.shape, op.confocal, np.dtype(op.options.dtype).itemsize)


def stack_size(planes: int, frequencies: int, padded: tuple[int, int],
               lattice: tuple[int, int], confocal: bool, itemsize: int) -> int:
    """Bytes of the stacked constants: kernel spectra (Z, F, Ly, Lx) on the ``padded``
    lattice and, unless ``confocal``, laser legs (Z, F, Y, X) on the voxel ``lattice``."""
    legs = 0 if confocal else math.prod(lattice)
    return planes * frequencies * (padded[0] * padded[1] + legs) * itemsize

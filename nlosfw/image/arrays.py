"""Where the FFT-based imagers compute: ``imager.device`` and the array backend it selects.

``fft``, ``lct``, ``fk`` and ``fbp`` take ``device``: ``cpu`` (the default) runs their
numpy code; ``cuda`` runs their heavy work (the FFTs, the products with the kernels' and
field's spectra, the sums over frequencies) through an array backend a plugin registers
(``register_array_backends``; the torch plugin's runs on CUDA), a one-line ConfigError
before the run when no registered backend sees a CUDA device; ``auto`` is ``cuda`` when
one is seen, else ``cpu``. Arrays stay numpy at the imager's boundary: the field in, the
:class:`~nlosfw.image.Reconstruction` out; what depends on the geometry alone (kernel
samples' distances, index maps) is computed with numpy and moved to the device.

An imager bound to a backend (:meth:`DeviceImager.on`) computes on it whatever its
``device`` option says: that is how the plugin layer hands it the backend the option
selects, and how a test runs the device code on a backend's CPU device.
"""

from __future__ import annotations

import copy
from typing import Any, Protocol, TypeAlias, TypeVar

import numpy as np

from nlosfw.common.config import Choice


class Device(Choice):
    """Where an FFT-based imager computes (see the module docstring)."""

    auto = "auto"
    cpu = "cpu"
    cuda = "cuda"


#: An array of a backend's library on its device (a ``torch.Tensor``, a numpy array):
#: typed by that library, which the core does not import.
DeviceArray: TypeAlias = Any


class ArrayOps(Protocol):
    """The array operations of the imagers' device code, on one device of one library.

    Arrays of the library support ``+ - * /``, ``@``, ``.conj()``, ``.real``, ``.imag``,
    basic slicing and slice assignment; the rest is here. ``dtype`` arguments are numpy
    dtypes (``np.complex64``, ``np.float32``, ``np.int64``, ...).
    """

    #: The device's name (``cuda``, ``cpu``), for the reconstruction's metadata.
    device: str

    def asarray(self, a: np.ndarray, dtype: type | None = None) -> DeviceArray:
        """``a`` on the device (as ``dtype`` when given)."""

    def numpy(self, a: DeviceArray) -> np.ndarray:
        """A device array back as a numpy array (a copy on the host)."""

    def zeros(self, shape: tuple[int, ...], dtype: type) -> DeviceArray:
        """A zeroed array on the device."""

    def fftn(self, a: DeviceArray, shape: tuple[int, ...], axes: tuple[int, ...]) -> DeviceArray:
        """The FFT over ``axes`` of ``a`` zero-padded (at the end) to ``shape`` there."""

    def ifftn(self, a: DeviceArray, axes: tuple[int, ...]) -> DeviceArray:
        """The inverse FFT over ``axes`` (normalised by the transform's size, as numpy)."""

    def einsum(self, subscripts: str, *operands: DeviceArray) -> DeviceArray:
        """``numpy.einsum``'s sum on the device."""

    def take_along_axis(self, a: DeviceArray, indices: DeviceArray, axis: int) -> DeviceArray:
        """``numpy.take_along_axis`` on the device."""

    def where(self, condition: DeviceArray, a: DeviceArray, b: DeviceArray) -> DeviceArray:
        """``numpy.where`` on the device (``b`` may be a scalar)."""

    def phasor(self, turns: DeviceArray, dtype: type) -> DeviceArray:
        """exp(2 pi i turns) as ``dtype`` (complex), ``turns`` real on the device."""


class DeviceImager:
    """What an imager with a ``device`` option has: the array backend it is bound to
    (None: its numpy code)."""

    arrays: ArrayOps | None = None

    def on(self: ImagerT, arrays: ArrayOps | None) -> ImagerT:
        """A copy of this imager that computes through ``arrays`` (None: numpy)."""
        bound = copy.copy(self)
        bound.arrays = arrays
        return bound

    def device_info(self) -> dict[str, object]:
        """The reconstruction's metadata of the device: ``{"device": name}`` when bound to
        an array backend, nothing for numpy (whose reconstructions stay as they were)."""
        return {} if self.arrays is None else {"device": self.arrays.device}


ImagerT = TypeVar("ImagerT", bound=DeviceImager)


def interpolate_depths_on(ops: ArrayOps, volume: DeviceArray, z0: float, dz: float,
                          depths: np.ndarray) -> np.ndarray:
    """:func:`nlosfw.image.transient.interpolate_depths` of a device volume: linear along
    axis 0 (planes z0 + k dz) at ``depths``, zero outside; the planes back as numpy."""
    pos = (np.asarray(depths, dtype=float) - z0) / dz
    i0 = np.floor(pos).astype(np.int64)
    frac = (pos - i0).astype(np.float32)[:, None, None]
    n = int(volume.shape[0])
    valid = [(i0 + k >= 0) & (i0 + k < n) for k in (0, 1)]
    planes = [ops.numpy(volume[ops.asarray(np.where(ok, i0 + k, 0), np.int64)])
              for k, ok in enumerate(valid)]
    a = np.where(valid[0][:, None, None], planes[0], 0)
    b = np.where(valid[1][:, None, None], planes[1], 0)
    return a * (1 - frac) + b * frac

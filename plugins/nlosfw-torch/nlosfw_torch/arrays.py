"""The torch array backend of the FFT-based imagers (:class:`nlosfw.image.arrays.ArrayOps`).

Registered as ``torch`` for ``cuda`` (:mod:`nlosfw_torch.hooks`); the same code runs on
torch's CPU device, which is how the tests check it against the numpy imagers on a
machine without a GPU.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from nlosfw.common import ConfigError

_DTYPES = {np.dtype(np.complex64): torch.complex64, np.dtype(np.complex128): torch.complex128,
           np.dtype(np.float32): torch.float32, np.dtype(np.float64): torch.float64,
           np.dtype(np.int64): torch.int64, np.dtype(np.int32): torch.int32,
           np.dtype(np.bool_): torch.bool}


def device_count(kind: str) -> int:
    """How many devices of ``kind`` (``cuda``) torch sees on this machine (no CUDA context
    is created)."""
    return int(torch.cuda.device_count()) if kind == "cuda" else 0


class TorchArrays:
    """Array operations on one torch device (``cuda``, ``cuda:N`` or ``cpu``)."""

    def __init__(self, device: str = "cuda") -> None:
        try:
            self._device = torch.device(device)
        except (RuntimeError, ValueError) as err:
            raise ConfigError("imager.device", f"torch does not know device {device!r} "
                              f"({err}); valid: auto, cpu, cuda") from None
        self.device = str(self._device)

    def _dtype(self, dtype: type | None) -> torch.dtype | None:
        return None if dtype is None else _DTYPES[np.dtype(dtype)]

    def asarray(self, a: np.ndarray, dtype: type | None = None) -> torch.Tensor:
        array = np.asarray(a)
        if dtype is not None:
            array = array.astype(dtype, copy=False)
        return torch.from_numpy(np.ascontiguousarray(array)).to(self._device)

    def numpy(self, a: torch.Tensor) -> np.ndarray:
        return np.asarray(a.detach().cpu().numpy())

    def zeros(self, shape: tuple[int, ...], dtype: type) -> torch.Tensor:
        return torch.zeros(shape, dtype=self._dtype(dtype), device=self._device)

    def fftn(self, a: torch.Tensor, shape: tuple[int, ...], axes: tuple[int, ...]
             ) -> torch.Tensor:
        return torch.fft.fftn(a, s=shape, dim=axes)

    def ifftn(self, a: torch.Tensor, axes: tuple[int, ...]) -> torch.Tensor:
        return torch.fft.ifftn(a, dim=axes)

    def einsum(self, subscripts: str, *operands: torch.Tensor) -> torch.Tensor:
        return torch.einsum(subscripts, *operands)

    def take_along_axis(self, a: torch.Tensor, indices: torch.Tensor, axis: int
                        ) -> torch.Tensor:
        return torch.take_along_dim(a, indices, dim=axis)

    def where(self, condition: torch.Tensor, a: torch.Tensor, b: Any) -> torch.Tensor:
        other = b if isinstance(b, torch.Tensor) else torch.zeros((), dtype=a.dtype,
                                                                  device=a.device) + b
        return torch.where(condition, a, other)

    def phasor(self, turns: torch.Tensor, dtype: type) -> torch.Tensor:
        angle = 2 * np.pi * torch.remainder(turns, 1.0)
        real = torch.cos(angle)
        out = torch.complex(real, torch.sin(angle))
        return out.to(self._dtype(dtype))

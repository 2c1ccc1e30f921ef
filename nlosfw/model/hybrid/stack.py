"""What the neural hidden volume's backends train with: the operator's constants stacked
over voxel planes (and their size, known before they are built), and the validation split
and kept step of the training (:mod:`nlosfw.model.neural_volume`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.model.scene_operator import SceneOperator


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
    """Bytes of :func:`plane_stack`'s arrays for ``op``: kernel spectra (Z, F, Ly, Lx) and,
    unless confocal, laser legs (Z, F, Y, X), in the operator's dtype; nothing is computed."""
    z, n_f = op.lattice.depths.size, op.frequencies.size
    itemsize = np.dtype(op.options.dtype).itemsize
    ly, lx = op.conv.shape
    legs = 0 if op.confocal else int(np.prod(op.lattice.shape))
    return z * n_f * (ly * lx + legs) * itemsize


def validation_split(shape: tuple[int, int], fraction: float, seed: int,
                     sampled: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """(train, validation) weights (ny, nx), float32 0/1: ``fraction`` of the sampled wall
    points (``sampled`` True, (ny, nx); None: every point), chosen at random with ``seed``,
    are validation points (none below 10 points or at 0); both are 0 where not sampled."""
    points = (np.arange(shape[0] * shape[1]) if sampled is None
              else np.flatnonzero(np.asarray(sampled, dtype=bool)))
    train = np.zeros(shape[0] * shape[1], np.float32)
    train[points] = 1
    n_val = int(round(fraction * points.size))
    if fraction <= 0 or points.size < 10 or n_val < 1:
        return train.reshape(shape), None
    chosen = points[np.random.default_rng(seed).permutation(points.size)[:n_val]]
    validation = np.zeros_like(train)
    validation[chosen] = 1
    train[chosen] = 0
    return train.reshape(shape), validation.reshape(shape)


def history_entry(step: int, loss: float, validation: float | None) -> dict[str, float]:
    """A fit-history entry of the backends' loops: the step, the training loss and, with
    validation points, their error (``val_loss``)."""
    entry: dict[str, float] = {"step": step, "loss": loss}
    if validation is not None:
        entry["val_loss"] = validation
    return entry


@dataclass
class BestStep:
    """The step with the lowest validation error so far (no validation: the latest) and its
    albedo (a backend array), for :meth:`NeuralVolumeFieldModel.train`'s loops."""

    patience: int
    step: int = 0
    error: float = float("inf")
    albedo: object = None

    def offer(self, step: int, error: float | None, albedo: object) -> None:
        """Keep ``albedo`` (the state before step ``step``'s update) if it is the best."""
        if error is None or error < self.error:
            self.step, self.error, self.albedo = step, math.inf if error is None else error, \
                albedo

    @property
    def validation(self) -> float | None:
        """The kept step's validation error (None: no validation)."""
        return self.error if math.isfinite(self.error) else None

    def stop(self, step: int) -> bool:
        """Whether ``patience`` steps passed without a better validation error."""
        return self.patience > 0 and math.isfinite(self.error) and \
            step - self.step >= self.patience

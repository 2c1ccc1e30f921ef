"""The ``fk`` imager: f-k (Stolt) migration of the field's confocal transient (Lindell 2019).

In a confocal scan the light travels to a point and back, so the transient at
distance d = t/2 is the wall recording of a wave emitted by the hidden scene at
d = 0 and travelling at unit speed (the exploding reflector). With psi(x, y, d)
the falloff-compensated transient (h d^(n-1): a scatterer's wave then falls off
as 1/r, like a point source's), its 3-D Fourier transform Psi(kx, ky, k_d) and
the dispersion relation k_d^2 = kx^2 + ky^2 + kz^2 (cycles per metre), the
scene is

    Phi(kx, ky, kz) = Psi(kx, ky, sqrt(kx^2 + ky^2 + kz^2)) kz / sqrt(kx^2 + ky^2 + kz^2)

for kz > 0 (zero otherwise), and phi(x, y, z) its inverse transform; the image is
|phi|^2. The transient h is analytic (positive frequencies only), so nothing is
lost by keeping kz > 0. Psi is sampled on the grid of the zero-padded (2x) FFT
and read at the Stolt-mapped k_d by linear interpolation (the published
method); with a time step dt the depth grid is dz = dt/2 and kz shares k_d's
sampling. Unlike the published code this works on the (complex, linear) field
transient, so there is no square root of the histogram (see
:mod:`nlosfw.image.transient`).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.image.arrays import ArrayOps, interpolate_depths_on
from nlosfw.image.transient import (
    TransientImager,
    TransientImagerConfig,
    WallGrid,
    interpolate_depths,
    lateral_frequencies,
    transient_sizes,
    wall_shape,
)
from nlosfw.transform.field import PhasorField

#: Depth steps (dt/2) of margin beyond the farthest voxel.
_MARGIN_STEPS = 4


class FKImager(TransientImager[TransientImagerConfig]):
    """f-k migration (Lindell 2019) of confocal fields."""

    config_class = TransientImagerConfig
    imager_name = "fk"

    def _planes(self, field: PhasorField, grid: WallGrid, depths: np.ndarray, dt: float,
                window: tuple[float, float]) -> tuple[np.ndarray, dict[str, object]]:
        dz = dt / 2
        far = math.hypot(float(depths.max()) + _MARGIN_STEPS * dz, grid.lateral_reach)
        n = math.ceil(2 * far / dt) + 1                        # t from 0 to the farthest path
        if self.arrays is not None:
            return self._planes_on(self.arrays, field, grid, depths, dt, window)
        h = self.transient(field, grid, np.arange(n) * dt, window)
        ny, nx = grid.shape
        shape = _fft_shape(n, ny, nx)
        workers = self.config.workers
        spectrum = scipy.fft.fftn(h, s=shape, workers=workers)
        half = shape[0] // 2                     # k_d = q / (shape[0] dz), q < half: positive
        q, source, i0, frac, inside = _stolt_map(shape, grid, dz)
        positive = spectrum[:half]
        a = np.take_along_axis(positive, i0, axis=0)
        b = np.take_along_axis(positive, i0 + 1, axis=0)
        migrated = np.zeros(shape, dtype=np.complex64)
        jacobian = (q[:, None, None] / np.maximum(source, 1e-6)).astype(np.float32)
        migrated[1:half] = np.where(inside, (a * (1 - frac) + b * frac) * jacobian, 0)
        del a, b, source, frac, i0, positive, spectrum
        volume = scipy.fft.ifftn(migrated, workers=workers, overwrite_x=True)[:n, :ny, :nx]
        return interpolate_depths(volume, 0.0, dz, depths), {"fft_shape": list(shape)}

    @classmethod
    def estimate_memory(cls, config: TransientImagerConfig, shape: PlanShape,
                        planes: int) -> MemoryEstimate:
        """About 6 times P, the padded complex64 volume of the transient's FFT (the spectrum,
        the Stolt map's samples, indices, weights and Jacobian, the two samples read and
        the migrated volume); P at the band's top and the depths' farthest when known, at
        2 x 2048 time samples otherwise."""
        wall = wall_shape(shape)
        reach, depths, dt = transient_sizes(config, shape)
        if depths is None or dt is None:
            n, why = 2048, "at most 2048 time samples (the band or depths not known yet)"
        else:
            far = math.hypot(depths[1] + _MARGIN_STEPS * dt / 2, reach)
            n, why = math.ceil(2 * far / dt) + 1, f"{math.ceil(2 * far / dt) + 1} time samples"
        padded = _fft_shape(n, *wall)
        return MemoryEstimate((MemoryPart(
            "the f-k volumes", f"6 x the padded volume {' x '.join(map(str, padded))} "
            f"(complex64; {why})", 6 * 8.0 * float(np.prod(padded))),))

    def _planes_on(self, ops: ArrayOps, field: PhasorField, grid: WallGrid, depths: np.ndarray,
                   dt: float, window: tuple[float, float]
                   ) -> tuple[np.ndarray, dict[str, object]]:
        """:meth:`_planes` on the device of ``ops``: the transient, its FFT, the Stolt
        interpolation and the inverse FFT there."""
        dz = dt / 2
        n = math.ceil(2 * math.hypot(float(depths.max()) + _MARGIN_STEPS * dz,
                                     grid.lateral_reach) / dt) + 1
        ny, nx = grid.shape
        shape = _fft_shape(n, ny, nx)
        coeffs = ops.asarray(self.window_coefficients(field, np.arange(n) * dt, window),
                             np.complex64)
        flat = ops.asarray(grid.values.reshape(grid.values.shape[0], -1), np.complex64)
        spectrum = ops.fftn((coeffs @ flat).reshape(n, ny, nx), shape, (0, 1, 2))
        half = shape[0] // 2
        q, source, i0, frac, inside = _stolt_map(shape, grid, dz)
        jacobian = (q[:, None, None] / np.maximum(source, 1e-6)).astype(np.float32)
        positive = spectrum[:half]
        index = ops.asarray(i0, np.int64)
        a = ops.take_along_axis(positive, index, 0)
        b = ops.take_along_axis(positive, index + 1, 0)
        weight = ops.asarray(frac, np.float32)
        migrated = ops.zeros(shape, np.complex64)
        migrated[1:half] = ops.where(ops.asarray(inside),
                                     (a * (1 - weight) + b * weight)
                                     * ops.asarray(jacobian, np.float32), 0)
        del a, b, spectrum, positive
        volume = ops.ifftn(migrated, (0, 1, 2))[:n, :ny, :nx]
        return (interpolate_depths_on(ops, volume, 0.0, dz, depths),
                {"fft_shape": list(shape), **self.device_info()})


def _fft_shape(n: int, ny: int, nx: int) -> tuple[int, int, int]:
    """The padded (2x) FFT shape of a transient of ``n`` samples on a ``ny`` x ``nx`` wall."""
    return (scipy.fft.next_fast_len(2 * n), scipy.fft.next_fast_len(2 * ny) if ny > 1 else 1,
            scipy.fft.next_fast_len(2 * nx) if nx > 1 else 1)


def _stolt_map(shape: tuple[int, int, int], grid: WallGrid, dz: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(q, source, i0, frac, inside): the Stolt map of the positive k_d samples q (1 to
    half - 1) onto the spectrum's samples, source = sqrt(q^2 + lateral) in index units,
    read between i0 and i0 + 1 at ``frac``; ``inside`` where i0 + 1 is a positive
    sample (i0 is 0 elsewhere)."""
    half = shape[0] // 2
    ky = lateral_frequencies(shape[1], grid.spacing[0])
    kx = lateral_frequencies(shape[2], grid.spacing[1])
    lateral = (shape[0] * dz) ** 2 * (ky[:, None] ** 2 + kx[None, :] ** 2)   # in index^2
    q = np.arange(1, half, dtype=np.float64)
    source = np.sqrt(q[:, None, None] ** 2 + lateral[None]).astype(np.float32)
    i0 = np.floor(source).astype(np.int32)
    frac = source - i0
    inside = i0 + 1 < half
    i0 = np.where(inside, i0, 0)
    return q, source, i0, frac, inside

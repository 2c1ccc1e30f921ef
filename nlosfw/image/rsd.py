"""The ``rsd`` imager: the direct Rayleigh-Sommerfeld sum over any voxel set.

For every voxel and frequency it sums the shared kernel of
:mod:`nlosfw.image.rsd_kernel` over every wall sample (thesis eq. 3.13-3.15):
O(voxels x wall samples x frequencies), exact, for planes, stacks of planes
or arbitrary points, and for any wall (no grid needed). Voxels are processed
in blocks whose kernel tables fit ``chunk_mb``, so memory stays bounded for
any number of voxels. The kernels of one block come one frequency at a time
from :func:`~nlosfw.image.rsd_kernel.phasor_steps` (for uniformly spaced
frequencies a recurrence that avoids one complex exponential per voxel, sample
and frequency), so no table over frequencies is ever stored.
Sums use numpy's own loops (``einsum``), not a multithreaded BLAS matrix-vector
product, whose speed collapses when the cores are shared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import require, require_threads
from nlosfw.common.cores import run_tasks, worker_count
from nlosfw.common.progress import ProgressCallback, ProgressCounter
from nlosfw.image.propagation import FrequencySum, PropagationConfig, PropagationImager
from nlosfw.image.rsd_kernel import laser_phase, path_multiplier, phasor_steps, wall_field
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True)
class RSDImagerConfig(PropagationConfig):
    """Options of the ``rsd`` imager."""

    chunk_mb: float = 2.0
    """[MiB] Memory of one block of voxel x wall-sample kernels, per worker (cache-sized blocks
    are fastest; total memory is about workers x this plus the output)."""
    workers: int = -1
    """Threads working on separate voxel blocks (-1: all cores)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.chunk_mb > 0, "chunk_mb", f"must be > 0 MiB, got {self.chunk_mb}")
        require_threads(self.workers, "workers", -1, "all cores")


class RSDImager(PropagationImager[RSDImagerConfig]):
    """Direct RSD sum of the phasor field at arbitrary voxels (exact, slower than ``fft``)."""

    config_class = RSDImagerConfig
    imager_name = "rsd"

    def _intensity(self, field: PhasorField, voxels: np.ndarray, coeffs: np.ndarray,
                   on_progress: ProgressCallback | None = None) -> np.ndarray:
        values = wall_field(field).reshape(field.n_frequencies, -1)          # (F, S)
        wall = field.wall_xyz.reshape(-1, 3)
        points = voxels.reshape(-1, 3)
        # Per voxel and wall sample: r and its temporaries, the kernel, the recurrence step.
        block = int(max(1, self.config.chunk_mb * 2**20 // (wall.shape[0] * 64)))
        starts = range(0, points.shape[0], block)
        out = np.empty((coeffs.shape[0], points.shape[0]), dtype=np.float64)
        progress = ProgressCounter(len(starts), on_progress)   # advanced from every worker

        def run(start: int) -> None:                # blocks write disjoint output columns
            vox = points[start:start + block]
            out[:, start:start + vox.shape[0]] = self._block(field, values, wall, vox, coeffs)
            progress.advance()

        run_tasks(run, starts, min(worker_count(self.config.workers), len(starts)))
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _block(self, field: PhasorField, values: np.ndarray, wall: np.ndarray, vox: np.ndarray,
               coeffs: np.ndarray) -> np.ndarray:
        """Intensities (n_t, n) of one block of voxels."""
        geometry = field.geometry
        m = path_multiplier(geometry)
        freqs = field.frequencies
        r = np.sqrt((vox[:, None, 0] - wall[None, :, 0]) ** 2
                    + (vox[:, None, 1] - wall[None, :, 1]) ** 2
                    + (vox[:, None, 2] - wall[None, :, 2]) ** 2)                # (n, S)
        fields = np.empty((freqs.size, vox.shape[0]), dtype=np.complex128)
        scale = 1.0 / r
        r *= m                                                         # the path m r
        for i, kern in phasor_steps(freqs, r, scale=scale):
            np.einsum("vs,s->v", kern, values[i], out=fields[i])
        phase = laser_phase(freqs, vox, geometry)
        if phase is not None:
            fields *= phase
        acc = FrequencySum(coeffs, self.config.combine, (vox.shape[0],))
        acc.add(fields)
        return acc.intensity()

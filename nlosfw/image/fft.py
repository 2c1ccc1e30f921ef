"""The ``fft`` imager: fast RSD (Liu 2020) by FFT convolution, plane by plane.

For a plane of voxels parallel to the wall, the shared kernel of
:mod:`nlosfw.image.rsd_kernel` depends on x_v - x_s only, so the sum over the
wall is a 2-D linear convolution of the wall field with the kernel sampled at
every voxel-sample offset. Both are zero-padded to (n_v + n_s - 1) per axis
(then to a fast FFT length), multiplied in the Fourier domain for all
frequencies at once, and transformed back: O(N^2 log N) per plane and
frequency instead of O(N^4). A volume is a stack of planes.

Voxel spacing may equal the wall spacing Δ or be a finer Δ/k (k an integer):
the wall field is then zero-interleaved onto the voxel lattice, which gives the
same sum exactly. Voxel planes need not be aligned with or as large as the
wall grid. The single-spot laser leg is a per-voxel phase applied after the
convolution; confocal fields use the doubled path (and, for coherent images,
sum the frequencies before a single inverse FFT).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.config import Choice, require
from nlosfw.common.errors import DataError
from nlosfw.common.progress import ProgressCallback, ProgressCounter
from nlosfw.image.grids import apply_ops, plane_grid, undo_ops, wall_grid
from nlosfw.image.propagation import FrequencySum, PropagationConfig, PropagationImager
from nlosfw.image.rsd_kernel import kernel, laser_phase, path_multiplier, wall_field
from nlosfw.transform.field import PhasorField


class Precision(Choice):
    """FFT precision: complex64 or complex128."""

    single = "single"
    double = "double"


@dataclass(frozen=True)
class FFTImagerConfig(PropagationConfig):
    """Options of the ``fft`` imager."""

    precision: Precision = Precision.single
    """FFT precision: complex64 (fast, ~1e-6 relative) or complex128."""
    workers: int = -1
    """Threads of scipy.fft (-1: all cores)."""
    chunk_mb: float = 512.0
    """[MiB] Memory of one batch of frequency planes; the field's spectrum is cached when it
    fits in half of this."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.workers == -1 or self.workers >= 1, "workers",
                f"must be -1 (all cores) or >= 1, got {self.workers}")
        require(self.chunk_mb > 0, "chunk_mb", f"must be > 0 MiB, got {self.chunk_mb}")


@dataclass(frozen=True)
class _Axis:
    """One axis of a voxel plane against the wall grid."""

    n_wall: int
    n_vox: int
    ratio: int            # k: wall spacing / voxel spacing
    step: float           # voxel spacing
    offset: float         # first voxel coordinate - first wall coordinate

    @property
    def n_interleaved(self) -> int:
        return self.ratio * (self.n_wall - 1) + 1

    @property
    def n_linear(self) -> int:
        return self.n_vox + self.n_interleaved - 1

    def offsets(self) -> np.ndarray:
        """Voxel - wall coordinate differences sampled by the linear convolution."""
        return self.offset + self.step * (np.arange(self.n_linear) - (self.n_interleaved - 1))


@dataclass(frozen=True, eq=False)
class _PlaneJob:
    """One voxel plane to image: the wall field (F, Y, X) in canonical order, its
    frequencies, the plane's voxels and depth, its convolution geometry, the path
    multiplier, the field's geometry, the coefficient rows, the shared spectrum cache and
    the FFT dtype."""

    values: np.ndarray
    freqs: np.ndarray
    plane: np.ndarray
    z: float
    ay: _Axis
    ax: _Axis
    m: int
    geometry: CaptureGeometry
    coeffs: np.ndarray
    cache: dict[tuple[int, ...], np.ndarray]
    cdtype: type


class FFTImager(PropagationImager):
    """Fast RSD for planes parallel to the wall on a regular grid (both capture kinds)."""

    config_class = FFTImagerConfig
    imager_name = "fft"

    # ------------------------------------------------------------------ checks
    def check_voxels(self, voxels: np.ndarray, field: PhasorField) -> np.ndarray:
        if voxels.ndim == 2:
            raise DataError(f"voxels: the fft imager needs planes parallel to the wall on a "
                            f"regular grid, (Y, X, 3) or (Z, Y, X, 3); got a point list "
                            f"{voxels.shape} (use the rsd imager for arbitrary points)")
        wall_grid(field)
        for i, plane in enumerate(voxels.reshape((-1,) + voxels.shape[-3:])):
            plane_grid(plane, i)
        return voxels

    # ------------------------------------------------------------------ imaging
    def _intensity(self, field: PhasorField, voxels: np.ndarray, coeffs: np.ndarray,
                   on_progress: ProgressCallback | None = None) -> np.ndarray:
        cfg = self.config
        cdtype = np.complex64 if cfg.precision == "single" else np.complex128
        ops, (wy0, wx0), (dy, dx) = wall_grid(field)
        values = apply_ops(wall_field(field, cdtype), ops, axes=(1, 2))
        geometry = field.geometry
        m = path_multiplier(geometry)
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        cache: dict[tuple[int, ...], np.ndarray] = {}
        progress = ProgressCounter(len(planes), on_progress)
        for i, plane in enumerate(planes):
            pops, (vy0, vx0), (vdy, vdx), z = plane_grid(plane, i)
            canon = apply_ops(plane, pops, axes=(0, 1))
            ay = _axis(values.shape[1], canon.shape[0], dy, vdy, vy0 - wy0, "y")
            ax = _axis(values.shape[2], canon.shape[1], dx, vdx, vx0 - wx0, "x")
            image = self._plane(_PlaneJob(values, field.frequencies, canon, z, ay, ax, m,
                                          geometry, coeffs, cache, cdtype))
            out[:, i] = undo_ops(image, pops, axes=(1, 2))
            progress.advance()
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _plane(self, job: _PlaneJob) -> np.ndarray:
        cfg = self.config
        values, freqs, plane, z = job.values, job.freqs, job.plane, job.z
        ay, ax, m, geometry = job.ay, job.ax, job.m, job.geometry
        coeffs, cache, cdtype = job.coeffs, job.cache, job.cdtype
        n_f = freqs.size
        shape = (scipy.fft.next_fast_len(ay.n_linear), scipy.fft.next_fast_len(ax.n_linear))
        itemsize = np.dtype(cdtype).itemsize
        plane_bytes = shape[0] * shape[1] * itemsize
        budget = cfg.chunk_mb * 2**20
        key = (ay.ratio, ax.ratio) + shape
        spectrum = cache.get(key)
        if spectrum is None and n_f * plane_bytes <= budget / 2:
            spectrum = cache[key] = self._spectrum(values, ay, ax, shape, slice(None))
        batch = int(max(1, budget // (4 * plane_bytes + 12 * ay.n_linear * ax.n_linear)))
        r = np.sqrt(ay.offsets()[:, None] ** 2 + ax.offsets()[None, :] ** 2 + z * z)
        crop = (slice(ay.n_interleaved - 1, ay.n_interleaved - 1 + ay.n_vox),
                slice(ax.n_interleaved - 1, ax.n_interleaved - 1 + ax.n_vox))
        coherent = cfg.combine == "coherent"
        fold = coherent and geometry.kind is CaptureKind.CONFOCAL   # no voxel phase: sum first
        acc = FrequencySum(coeffs, cfg.combine, (ay.n_vox, ax.n_vox))
        folded = np.zeros((coeffs.shape[0],) + shape, dtype=np.complex128) if fold else None
        for start in range(0, n_f, batch):
            sel = slice(start, min(n_f, start + batch))
            spec = spectrum[sel] if spectrum is not None else self._spectrum(
                values, ay, ax, shape, sel)
            work = np.zeros((spec.shape[0],) + shape, dtype=cdtype)
            kernel(freqs[sel], r, m, cdtype, out=work[:, :ay.n_linear, :ax.n_linear])
            work = scipy.fft.fft2(work, overwrite_x=True, workers=cfg.workers)
            work *= spec
            if folded is not None:
                folded += np.einsum("tf,fyx->tyx", coeffs[:, sel], work)
                continue
            fields = scipy.fft.ifft2(work, overwrite_x=True, workers=cfg.workers)[
                (slice(None),) + crop]
            phase = laser_phase(freqs[sel], plane, geometry, cdtype)
            if phase is not None:
                fields *= phase
            acc.add(fields, sel)
        if folded is not None:
            amp = scipy.fft.ifft2(folded, overwrite_x=True, workers=cfg.workers)
            acc.add_amplitude(amp[(slice(None),) + crop])
        return acc.intensity()

    def _spectrum(self, values: np.ndarray, ay: _Axis, ax: _Axis, shape: tuple[int, int],
                  sel: slice) -> np.ndarray:
        """FFT of the wall field, zero-interleaved by the voxel/wall spacing ratio."""
        v = values[sel]
        grid = np.zeros((v.shape[0], ay.n_interleaved, ax.n_interleaved), dtype=v.dtype)
        grid[:, ::ay.ratio, ::ax.ratio] = v
        return scipy.fft.fft2(grid, s=shape, workers=self.config.workers)


def _axis(n_wall: int, n_vox: int, wall_step: float, vox_step: float, offset: float,
          name: str) -> _Axis:
    """The convolution geometry along one axis; DataError unless vox_step = wall_step / k."""
    if n_wall == 1 and n_vox == 1:
        return _Axis(1, 1, 1, 1.0, offset)
    if n_wall == 1:
        return _Axis(1, n_vox, 1, vox_step, offset)
    if n_vox == 1:
        return _Axis(n_wall, 1, 1, wall_step, offset)
    ratio = wall_step / vox_step
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > 1e-3 * ratio:
        raise DataError(f"voxels: {name} spacing {vox_step:.6g} m must be the wall spacing "
                        f"{wall_step:.6g} m divided by a whole number k >= 1 (got ratio "
                        f"{ratio:.6g}); use the rsd imager for other spacings")
    return _Axis(n_wall, n_vox, k, wall_step / k, offset)

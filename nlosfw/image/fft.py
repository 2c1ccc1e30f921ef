"""The ``fft`` imager: fast RSD (Liu 2020) by FFT convolution, plane by plane.

For a plane of voxels parallel to the wall, the shared kernel of
:mod:`nlosfw.image.rsd_kernel` depends on x_v - x_s only, so the sum over the
wall is a 2-D linear convolution of the wall field with the kernel sampled at
every voxel-sample offset. Both are zero-padded to the linear convolution's
length per axis (then to a fast FFT length), multiplied in the Fourier domain for
all frequencies at once, and transformed back: O(N^2 log N) per plane and
frequency instead of O(N^4). A volume is a stack of planes.

Voxel spacing may equal the wall spacing Δ, be a finer Δ/k or a coarser kΔ (k an
integer, per axis): the convolution then runs on the finer of the two lattices, the
wall field zero-interleaved onto it or the voxels read every k-th point, which gives
the same sum exactly. The layout (grid orientation, lattice, padding, where the wall
goes and the voxels are read) is :mod:`nlosfw.image.plane_convolution`, shared with
the ``rsd_prior`` field model. Voxel planes need not be aligned with or as large as
the wall grid. The single-spot laser leg is a per-voxel phase applied after the
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
from nlosfw.image.plane_convolution import (
    LatticeAxis,
    PlaneConvolution,
    from_canonical,
    lattice_axis,
    plane_layout,
    to_canonical,
    wall_layout,
)
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


@dataclass(frozen=True, eq=False)
class _PlaneJob:
    """One voxel plane to image: the wall field (F, Y, X) in canonical order, its
    frequencies, the plane's voxels (canonical order) and depth, its convolution layout,
    the path multiplier, the field's geometry, the coefficient rows, the shared spectrum
    cache and the FFT dtype."""

    values: np.ndarray
    freqs: np.ndarray
    plane: np.ndarray
    z: float
    conv: PlaneConvolution
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
        wall_layout(field)
        for i, plane in enumerate(voxels.reshape((-1,) + voxels.shape[-3:])):
            plane_layout(plane, i)
        return voxels

    # ------------------------------------------------------------------ imaging
    def _intensity(self, field: PhasorField, voxels: np.ndarray, coeffs: np.ndarray,
                   on_progress: ProgressCallback | None = None) -> np.ndarray:
        cfg = self.config
        cdtype = np.complex64 if cfg.precision == "single" else np.complex128
        wall = wall_layout(field)
        values = to_canonical(wall_field(field, cdtype), wall.order, axes=(1, 2))
        geometry = field.geometry
        m = path_multiplier(geometry)
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        cache: dict[tuple[int, ...], np.ndarray] = {}
        progress = ProgressCounter(len(planes), on_progress)
        for i, plane in enumerate(planes):
            grid, z = plane_layout(plane, i)
            canon = to_canonical(plane, grid.order, axes=(0, 1))
            conv = PlaneConvolution(
                _axis(wall.shape[0], wall.spacing[0], grid.shape[0], grid.spacing[0],
                      grid.origin[0] - wall.origin[0], "y"),
                _axis(wall.shape[1], wall.spacing[1], grid.shape[1], grid.spacing[1],
                      grid.origin[1] - wall.origin[1], "x"),
                cfg.workers)
            image = self._plane(_PlaneJob(values, field.frequencies, canon, z, conv, m,
                                          geometry, coeffs, cache, cdtype))
            out[:, i] = from_canonical(image, grid.order, axes=(1, 2))
            progress.advance()
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _plane(self, job: _PlaneJob) -> np.ndarray:
        cfg = self.config
        values, freqs, plane, z = job.values, job.freqs, job.plane, job.z
        conv, m, geometry = job.conv, job.m, job.geometry
        coeffs, cache, cdtype = job.coeffs, job.cache, job.cdtype
        n_f = freqs.size
        shape = conv.shape
        itemsize = np.dtype(cdtype).itemsize
        plane_bytes = shape[0] * shape[1] * itemsize
        budget = cfg.chunk_mb * 2**20
        key = conv.input_key
        spectrum = cache.get(key)
        if spectrum is None and n_f * plane_bytes <= budget / 2:
            spectrum = cache[key] = conv.input_spectrum(values)
        batch = int(max(1, budget // (4 * plane_bytes
                                      + 12 * conv.ay.n_linear * conv.ax.n_linear)))
        r = conv.distances(z)
        coherent = cfg.combine == "coherent"
        fold = coherent and geometry.kind is CaptureKind.CONFOCAL   # no voxel phase: sum first
        acc = FrequencySum(coeffs, cfg.combine, (conv.ay.n_out, conv.ax.n_out))
        folded = np.zeros((coeffs.shape[0],) + shape, dtype=np.complex128) if fold else None
        for start in range(0, n_f, batch):
            sel = slice(start, min(n_f, start + batch))
            spec = spectrum[sel] if spectrum is not None else conv.input_spectrum(values[sel])
            work = conv.padded(spec.shape[0], cdtype)
            kernel(freqs[sel], r, m, cdtype, out=work[(slice(None),) + conv.kernel_region])
            work = scipy.fft.fft2(work, overwrite_x=True, workers=cfg.workers)
            work *= spec
            if folded is not None:
                # the sum over frequencies as one matrix product (BLAS), in the work
                # array's precision: an einsum here was a third of the plane's time
                rows = coeffs[:, sel].astype(work.dtype)
                folded += (rows @ work.reshape(work.shape[0], -1)).reshape(
                    (rows.shape[0],) + shape)
                continue
            fields = conv.read_outputs(work)
            phase = laser_phase(freqs[sel], plane, geometry, cdtype)
            if phase is not None:
                fields *= phase
            acc.add(fields, sel)
        if folded is not None:
            acc.add_amplitude(conv.read_outputs(folded))
        return acc.intensity()


def _axis(n_wall: int, wall_step: float, n_vox: int, vox_step: float, offset: float,
          name: str) -> LatticeAxis:
    """The convolution from the wall to the voxels along one axis; DataError unless one
    spacing is a whole multiple of the other."""
    axis = lattice_axis(n_wall, wall_step, n_vox, vox_step, offset)
    if axis is None:
        raise DataError(f"voxels: {name} spacing {vox_step:.6g} m must be the wall spacing "
                        f"{wall_step:.6g} m divided or multiplied by a whole number k >= 1 "
                        f"(got ratio {wall_step / vox_step:.6g}); use the rsd imager for other "
                        "spacings")
    return axis

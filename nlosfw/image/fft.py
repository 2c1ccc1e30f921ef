"""The ``fft`` imager: fast RSD (Liu 2020) by FFT convolution, plane by plane.

For a plane of voxels parallel to the wall, the shared kernel of
:mod:`nlosfw.image.rsd_kernel` depends on x_v - x_s only, so the sum over the
wall is a 2-D linear convolution of the wall field with the kernel sampled at
every voxel-sample offset. Both are zero-padded to (n_v + n_s - 1) per axis
(then to a fast FFT length), multiplied in the Fourier domain for all
frequencies at once, and transformed back: O(N^2 log N) per plane and
frequency instead of O(N^4). A volume is a stack of planes.

Voxel spacing may equal the wall spacing Δ, be a finer Δ/k or a coarser kΔ (k an
integer): the convolution then runs on the finer of the two lattices, the wall field
zero-interleaved onto it or the voxels read every k-th point, which gives the same sum
exactly (the layout is :mod:`nlosfw.image.plane_convolution`, shared with the
``rsd_prior`` field model). Voxel planes need not be aligned with or as large as the
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
from nlosfw.image.plane_convolution import (
    GridLayout,
    LatticeAxis,
    PlaneConvolution,
    from_canonical,
    grid_layout,
    lattice_axis,
    to_canonical,
)
from nlosfw.image.propagation import FrequencySum, PropagationConfig, PropagationImager
from nlosfw.image.rsd_kernel import kernel, laser_phase, path_multiplier, wall_field
from nlosfw.transform.field import PhasorField

#: Relative tolerance on "voxel spacing = wall spacing / k" and on plane flatness.
_RTOL = 1e-6


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
    """Memory (MiB) of one batch of frequency planes; the field's spectrum is cached when it
    fits in half of this."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.workers == -1 or self.workers >= 1, "workers",
                f"must be -1 (all cores) or >= 1, got {self.workers}")
        require(self.chunk_mb > 0, "chunk_mb", f"must be > 0 MiB, got {self.chunk_mb}")


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
        _wall_grid(field)
        for i, plane in enumerate(voxels.reshape((-1,) + voxels.shape[-3:])):
            _plane_grid(plane, i)
        return voxels

    # ------------------------------------------------------------------ imaging
    def _intensity(self, field: PhasorField, voxels: np.ndarray,
                   coeffs: np.ndarray) -> np.ndarray:
        cfg = self.config
        cdtype = np.complex64 if cfg.precision == "single" else np.complex128
        wall = _wall_grid(field)
        values = to_canonical(wall_field(field, cdtype), wall.order, axes=(1, 2))
        geometry = field.geometry
        m = path_multiplier(geometry)
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        cache: dict[tuple[int, ...], np.ndarray] = {}
        for i, plane in enumerate(planes):
            grid, z = _plane_grid(plane, i)
            canon = to_canonical(plane, grid.order, axes=(0, 1))
            conv = PlaneConvolution(
                _axis(wall.shape[0], wall.spacing[0], grid.shape[0], grid.spacing[0],
                      grid.origin[0] - wall.origin[0], "y"),
                _axis(wall.shape[1], wall.spacing[1], grid.shape[1], grid.spacing[1],
                      grid.origin[1] - wall.origin[1], "x"),
                cfg.workers)
            image = self._plane(values, field.frequencies, canon, z, conv, m, geometry,
                                coeffs, cache, cdtype)
            out[:, i] = from_canonical(image, grid.order, axes=(1, 2))
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _plane(self, values: np.ndarray, freqs: np.ndarray, plane: np.ndarray, z: float,
               conv: PlaneConvolution, m: int, geometry: CaptureGeometry, coeffs: np.ndarray,
               cache: dict, cdtype: type) -> np.ndarray:
        cfg = self.config
        n_f = freqs.size
        shape = conv.shape
        n_lin = (conv.ay.n_linear, conv.ax.n_linear)
        itemsize = np.dtype(cdtype).itemsize
        plane_bytes = shape[0] * shape[1] * itemsize
        budget = cfg.chunk_mb * 2**20
        key = conv.input_key
        spectrum = cache.get(key)
        if spectrum is None and n_f * plane_bytes <= budget / 2:
            spectrum = cache[key] = conv.input_spectrum(values)
        batch = int(max(1, budget // (4 * plane_bytes + 12 * n_lin[0] * n_lin[1])))
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
                folded += np.einsum("tf,fyx->tyx", coeffs[:, sel], work)
                continue
            fields = conv.read_outputs(work)
            phase = laser_phase(freqs[sel], plane, geometry, cdtype)
            if phase is not None:
                fields *= phase
            acc.add(fields, sel)
        if folded is not None:
            acc.add_amplitude(conv.read_outputs(folded))
        return acc.intensity()


# ---------------------------------------------------------------------- grids
def _wall_grid(field: PhasorField) -> GridLayout:
    """The canonical layout of the field's wall; DataError if it is not a regular grid."""
    layout = grid_layout(field.wall_xyz)
    if layout is None:
        raise DataError("field.wall_xyz: the fft imager needs the field on a regular, "
                        "axis-aligned wall grid in the plane z = 0; use the rsd imager for "
                        "other walls")
    return layout


def _plane_grid(plane: np.ndarray, index: int) -> tuple[GridLayout, float]:
    """(layout, z) of one voxel plane; DataError unless it is a regular grid parallel to
    the wall."""
    z = plane[..., 2]
    scale = max(1.0, float(np.abs(z).max()), float(np.ptp(plane[..., :2])))
    if np.ptp(z) > _RTOL * scale:
        raise DataError(f"voxels: plane {index} is not parallel to the wall (z from "
                        f"{z.min():.6g} to {z.max():.6g} m); the fft imager needs planes of "
                        "constant z on a regular x-y grid; use the rsd imager for other voxels")
    layout = grid_layout(plane[..., :2])
    if layout is None:
        raise DataError(f"voxels: plane {index} is not a regular axis-aligned x-y grid; the fft "
                        "imager needs regularly spaced planes parallel to the wall; use the rsd "
                        "imager for other voxels")
    return layout, float(z.mean())


def _axis(n_wall: int, wall_step: float, n_vox: int, vox_step: float, offset: float,
          name: str) -> LatticeAxis:
    """The convolution from the wall to the voxels along one axis; DataError unless one
    spacing is a whole multiple of the other."""
    axis = lattice_axis(n_wall, wall_step, n_vox, vox_step, offset)
    if axis is None:
        raise DataError(f"voxels: {name} spacing {vox_step:.6g} m must be the wall spacing "
                        f"{wall_step:.6g} m divided or multiplied by a whole number (got ratio "
                        f"{wall_step / vox_step:.6g}); use the rsd imager for other spacings")
    return axis

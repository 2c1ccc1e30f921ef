"""The ``fft`` imager: fast RSD (Liu 2020) by FFT convolution, plane by plane.

For a plane of voxels parallel to the wall, the shared kernel of
:mod:`nlosfw.image.rsd_kernel` depends on x_v - x_s only, so the sum over the
wall is a 2-D linear convolution of the wall field with the kernel sampled at
every voxel-sample offset. Both are zero-padded to the linear convolution's
length per axis (then to a fast FFT length), multiplied in the Fourier domain and
transformed back: O(N^2 log N) per plane and frequency instead of O(N^4). A volume is
a stack of planes.

Voxel spacing may equal the wall spacing Δ, be a finer Δ/k or a coarser kΔ (k an
integer, per axis): the convolution then runs on the finer of the two lattices, the
wall field zero-interleaved onto it or the voxels read every k-th point, which gives
the same sum exactly. The layout (grid orientation, lattice, padding, where the wall
goes and the voxels are read) is :mod:`nlosfw.image.plane_convolution`, shared with
the ``rsd_prior`` field model. Voxel planes need not be aligned with or as large as
the wall grid. The single-spot laser leg is a per-voxel phase applied after the
convolution; confocal fields use the doubled path (and, for coherent images,
sum the frequencies before a single inverse FFT per plane).

Speed: planes are imaged in parallel threads (``workers``), and each plane runs over
blocks of a few frequencies whose padded arrays stay in the core's cache from the
kernel (:func:`~nlosfw.image.rsd_kernel.kernel_blocks`: one complex product per
value) through its FFT, the product with the field's cached spectrum and the sum
over frequencies. Coherent confocal images of the wall's own grid (the usual volume:
same extent, no offset) have an even kernel: its spectrum is a type-I DCT of a
quarter of it and the frequency sum runs on a quarter grid
(:mod:`nlosfw.image.even_kernel`), the same sum to rounding.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.fft

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.config import Choice, require, require_threads
from nlosfw.common.cores import run_tasks, worker_count
from nlosfw.common.errors import DataError
from nlosfw.common.progress import ProgressCallback, ProgressCounter
from nlosfw.image import even_kernel
from nlosfw.image.plane_convolution import (
    GridLayout,
    GridOrder,
    LatticeAxis,
    PlaneConvolution,
    from_canonical,
    lattice_axis,
    plane_layout,
    to_canonical,
    wall_layout,
)
from nlosfw.image.propagation import FrequencySum, PropagationConfig, PropagationImager
from nlosfw.image.rsd_kernel import (
    kernel_blocks,
    laser_distances,
    path_multiplier,
    phasor_blocks,
    wall_field,
)
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
    """Threads (-1: all cores): depth planes are imaged in parallel, and the threads left
    over when there are fewer planes split each plane's FFTs."""
    chunk_mb: float = 512.0
    """[MiB] Memory budget: the field's spectrum is cached when it fits in half of this;
    each thread works on blocks of at most a few MiB of frequency planes."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require_threads(self.workers, "workers", -1, "all cores")
        require(self.chunk_mb > 0, "chunk_mb", f"must be > 0 MiB, got {self.chunk_mb}")


@dataclass(frozen=True, eq=False)
class _Plane:
    """One voxel plane to image: its voxels in canonical order, that order, its depth and
    its convolution layout."""

    voxels: np.ndarray
    order: GridOrder
    z: float
    conv: PlaneConvolution
    even: bool
    """Whether its frequencies are folded on an even kernel (:mod:`nlosfw.image.even_kernel`)."""

    @property
    def spectrum_key(self) -> tuple[int, ...]:
        """Equal for planes that use the same cached spectrum."""
        return self.conv.input_key + (int(self.even),)


@dataclass(frozen=True, eq=False)
class _Volume:
    """What every plane of one reconstruction shares: the wall field (F, Y, X) in
    canonical order, its frequencies, the path multiplier, the geometry, the coefficient
    rows, the cached spectra per :attr:`_Plane.spectrum_key` (None: computed per block),
    whether the coefficients are already in them, and the FFT dtype."""

    values: np.ndarray
    freqs: np.ndarray
    m: int
    geometry: CaptureGeometry
    coeffs: np.ndarray
    spectra: dict[tuple[int, ...], np.ndarray | None]
    weighted: bool
    cdtype: type


class FFTImager(PropagationImager[FFTImagerConfig]):
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
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        cores = worker_count(cfg.workers)
        threads = min(cores, len(planes))                   # planes imaged in parallel
        fft_workers = max(1, cores // threads)              # the rest split each FFT
        fold = self._folds(field.geometry)
        layouts = [_plane(wall, plane, i, fft_workers, fold) for i, plane in enumerate(planes)]
        # confocal coherent images of one virtual time: the coefficients go into the
        # spectrum once, and each block's sum over frequencies is a plain sum
        weighted = fold and coeffs.shape[0] == 1
        volume = _Volume(values, field.frequencies, path_multiplier(field.geometry),
                         field.geometry, coeffs,
                         self._spectra(values, layouts, coeffs[0] if weighted else None),
                         weighted, cdtype)
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        progress = ProgressCounter(len(planes), on_progress)   # advanced from every thread

        def image(i: int) -> None:                  # planes write disjoint output slices
            layout = layouts[i]
            out[:, i] = from_canonical(self._image_plane(volume, layout), layout.order,
                                       axes=(1, 2))
            progress.advance()

        run_tasks(image, range(len(planes)), threads)
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _folds(self, geometry: CaptureGeometry) -> bool:
        """Whether frequencies are summed before a single inverse FFT per plane (coherent
        confocal images: no per-voxel phase)."""
        return self.config.combine == "coherent" and geometry.kind is CaptureKind.CONFOCAL

    def _spectra(self, values: np.ndarray, layouts: list[_Plane],
                 weights: np.ndarray | None) -> dict[tuple[int, ...], np.ndarray | None]:
        """The wall field's spectrum per :attr:`_Plane.spectrum_key` (times ``weights`` per
        frequency when given; its four mirror images for an even kernel), None for those
        that do not fit in what is left of half of ``chunk_mb``."""
        budget = self.config.chunk_mb * 2**20 / 2
        spectra: dict[tuple[int, ...], np.ndarray | None] = {}
        for layout in layouts:
            if layout.spectrum_key in spectra:
                continue
            shape = layout.conv.shape
            if layout.even:
                shape = (4 * (shape[0] // 2 + 1), shape[1] // 2 + 1)
            nbytes = values.shape[0] * shape[0] * shape[1] * values.itemsize
            spectrum = None
            if nbytes <= budget:
                spectrum = _spectrum(values, layout, weights)
                budget -= nbytes
            spectra[layout.spectrum_key] = spectrum
        return spectra

    def _block_size(self, conv: PlaneConvolution, cdtype: type) -> int:
        """Frequencies per block: about 512 KiB of padded planes (they stay in the core's
        cache through the kernel, FFT, product and sum), within ``chunk_mb``."""
        plane_bytes = conv.shape[0] * conv.shape[1] * np.dtype(cdtype).itemsize
        cached = int(np.clip(_BLOCK_BYTES // plane_bytes, 2, 16))
        return max(1, min(cached, int(self.config.chunk_mb * 2**20 // (8 * plane_bytes))))

    def _image_plane(self, volume: _Volume, layout: _Plane) -> np.ndarray:
        """Intensities (n_t, Y, X) of one plane, in canonical order."""
        if layout.even:
            return self._image_even_plane(volume, layout)
        conv, freqs, coeffs = layout.conv, volume.freqs, volume.coeffs
        work = conv.padded(self._block_size(conv, volume.cdtype), volume.cdtype)
        kernels = work[(slice(None),) + conv.kernel_region]
        spectrum = volume.spectra[layout.spectrum_key]
        fold = self._folds(volume.geometry)
        folded = np.zeros((coeffs.shape[0],) + conv.shape, dtype=volume.cdtype) if fold else None
        acc = FrequencySum(coeffs, self.config.combine, (conv.ay.n_out, conv.ax.n_out))
        blocks = kernel_blocks(freqs, conv.distances(layout.z), volume.m, kernels)
        r_l = laser_distances(layout.voxels, volume.geometry)
        laser: np.ndarray | None = None
        if r_l is not None:                         # the laser leg's phasors, block by block
            laser = np.empty((work.shape[0],) + r_l.shape, dtype=volume.cdtype)
            blocks = _same_blocks(blocks, phasor_blocks(freqs, r_l, laser))
        for sel in blocks:
            k = sel.stop - sel.start
            block = scipy.fft.fft2(work[:k], overwrite_x=True, workers=conv.workers)
            block *= (spectrum[sel] if spectrum is not None
                      else _spectrum(volume.values[sel], layout,
                                     coeffs[0, sel] if volume.weighted else None))
            if folded is not None:
                if volume.weighted:
                    folded[0] += block.sum(axis=0)
                else:
                    folded += np.einsum("tf,fyx->tyx", coeffs[:, sel].astype(volume.cdtype),
                                        block)
            else:
                fields = conv.read_outputs(block)
                if laser is not None:
                    fields *= laser[:k]
                acc.add(fields, sel)
            conv.clear_padding(work)
        if folded is not None:
            acc.add_amplitude(conv.read_outputs(folded))
        return acc.intensity()

    def _image_even_plane(self, volume: _Volume, layout: _Plane) -> np.ndarray:
        """Intensities (n_t, Y, X) of one plane whose frequencies fold on an even kernel:
        the sum over frequencies on the quarter grid, once per mirror image of the
        spectrum, then one full inverse FFT (:mod:`nlosfw.image.even_kernel`)."""
        conv, freqs, coeffs, cdtype = layout.conv, volume.freqs, volume.coeffs, volume.cdtype
        quarter = even_kernel.quarter_shape(conv)
        work = np.zeros((self._block_size(conv, cdtype),) + quarter, dtype=cdtype)
        kernels = work[(slice(None),) + even_kernel.kernel_region(conv)]
        spectrum = volume.spectra[layout.spectrum_key]
        sums = np.zeros((2, 2, coeffs.shape[0]) + quarter, dtype=cdtype)
        products = np.empty((2, 2, work.shape[0]) + quarter, dtype=cdtype)
        rows: np.ndarray = coeffs.astype(cdtype)
        for sel in kernel_blocks(freqs, even_kernel.distances(conv, layout.z), volume.m,
                                 kernels):
            k = sel.stop - sel.start
            block = even_kernel.kernel_spectrum(work[:k], conv.workers)
            images = (spectrum[:, :, sel] if spectrum is not None
                      else _spectrum(volume.values[sel], layout,
                                     coeffs[0, sel] if volume.weighted else None))
            product = np.multiply(images, block, out=products[:, :, :k])  # (2, 2, k, hy, hx)
            if volume.weighted:
                sums[:, :, 0] += product.sum(axis=2)
            else:
                sums += np.einsum("tf,abfyx->abtyx", rows[:, sel], product)
            even_kernel.clear_padding(conv, work)
        acc = FrequencySum(coeffs, self.config.combine, (conv.ay.n_out, conv.ax.n_out))
        acc.add_amplitude(even_kernel.read_outputs(conv, even_kernel.assemble(sums)))
        return acc.intensity()


def _spectrum(values: np.ndarray, layout: _Plane, weights: np.ndarray | None) -> np.ndarray:
    """The spectrum of wall fields (F, Y, X) on the plane's layout, times ``weights`` (F,)
    when given; its four mirror images (2, 2, F, hy, hx) for an even kernel."""
    spectrum = layout.conv.input_spectrum(values)
    if weights is not None:
        spectrum *= weights.astype(values.dtype)[:, None, None]
    return even_kernel.quarters(spectrum) if layout.even else spectrum


def _plane(wall: GridLayout, plane: np.ndarray, index: int, workers: int,
           fold: bool) -> _Plane:
    """The layout of voxel plane ``index`` against the wall (DataError for a spacing the
    FFT convolution cannot take); ``fold``: frequencies are summed before the inverse
    FFT."""
    grid, z = plane_layout(plane, index)
    ay = _axis(wall.shape[0], wall.spacing[0], grid.shape[0], grid.spacing[0],
               grid.origin[0] - wall.origin[0], "y")
    ax = _axis(wall.shape[1], wall.spacing[1], grid.shape[1], grid.spacing[1],
               grid.origin[1] - wall.origin[1], "x")
    even = even_kernel.even_layout(ay, ax, workers) if fold else None
    conv = even if even is not None else PlaneConvolution(ay, ax, workers)
    return _Plane(to_canonical(plane, grid.order, axes=(0, 1)), grid.order, z, conv,
                  even is not None)


def _same_blocks(first: Iterator[slice], second: Iterator[slice]) -> Iterator[slice]:
    """Advance two block generators over the same frequencies together."""
    for a, b in zip(first, second, strict=True):
        if a != b:
            raise RuntimeError(f"block generators out of step: {a} and {b}")
        yield a


#: Target bytes of one block of padded frequency planes (per thread).
_BLOCK_BYTES = 2**19


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

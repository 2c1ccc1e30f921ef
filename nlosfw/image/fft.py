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
over frequencies; the inverse FFTs run along y, then along x on the voxels' rows alone.
Voxel planes on the wall's own grid (the usual volume: same extent, no offset) have an
even kernel: its spectrum is a type-I DCT of a quarter of it
(:mod:`nlosfw.image.even_kernel`), and coherent confocal images sum the frequencies on
a quarter grid, the same sum to rounding. In single precision, coherent confocal
images of one virtual time with uniformly spaced frequencies transform a few time
slices of the kernel instead of every frequency's (:mod:`nlosfw.image.time_slices`:
37 to 47 slices for 151 frequencies on a 2 m wall), the direct sum to about 1e-6 of
the image's peak; ``precision=double`` transforms every frequency's kernel, the direct
sum to rounding.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.fft

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.config import Choice, require, require_threads
from nlosfw.common.cores import run_tasks, worker_count
from nlosfw.common.errors import DataError
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.common.progress import ProgressCallback, ProgressCounter
from nlosfw.image import even_kernel, time_slices
from nlosfw.image.arrays import ArrayOps, Device, DeviceArray, DeviceImager
from nlosfw.image.plane_convolution import (
    GridLayout,
    GridOrder,
    LatticeAxis,
    PlaneConvolution,
    from_canonical,
    lattice_axis,
    plane_layouts,
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
from nlosfw.image.time_slices import TimeSlices
from nlosfw.transform.field import PhasorField


class Precision(Choice):
    """FFT precision: complex64 (and the fast paths) or complex128 (exact)."""

    single = "single"
    double = "double"


@dataclass(frozen=True)
class FFTImagerConfig(PropagationConfig):
    """Options of the ``fft`` imager."""

    precision: Precision = Precision.single
    """``single``: complex64 and, for coherent confocal images, a few time slices of the
    kernel instead of every frequency's (fast, ~1e-6 of the peak from the direct sum);
    ``double``: complex128, every frequency's kernel (exact to rounding)."""
    workers: int = -1
    """Threads (-1: all cores): depth planes are imaged in parallel, and the threads left
    over when there are fewer planes split each plane's FFTs."""
    chunk_mb: float = 512.0
    """[MiB] Memory budget: the field's spectrum (on frequencies or time slices) is cached
    when it fits in half of this; the threads' blocks of kernels stay within the other
    half."""
    device: Device = Device.cpu
    """``cpu``: numpy; ``cuda``: the kernels, FFTs, products and sums over frequencies on
    a CUDA device through an array backend plugin (nlosfw-torch), every frequency's
    kernel transformed (no time slices); ``auto``: cuda when one is seen, else cpu
    (:mod:`nlosfw.image.arrays`)."""

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
    """Whether its kernel is even: its spectrum is the type-I DCT of its quarter
    (:mod:`nlosfw.image.even_kernel`)."""
    folded: bool
    """Whether its frequencies are also summed on the quarter grid (coherent confocal)."""

    def distances(self) -> np.ndarray:
        """|x_v - x_s| on the kernel's samples (its quarter when it is even)."""
        return (even_kernel.distances(self.conv, self.z) if self.even
                else self.conv.distances(self.z))

    @property
    def spectrum_key(self) -> tuple[int, ...]:
        """Equal for planes that use the same cached spectrum."""
        return self.conv.input_key + (int(self.folded),)


@dataclass(frozen=True, eq=False)
class _Volume:
    """What every plane of one reconstruction shares: the wall field (F, Y, X) in
    canonical order, its frequencies, the path multiplier, the geometry, the coefficient
    rows, the cached spectra per :attr:`_Plane.spectrum_key` (None: computed per block),
    whether the coefficients are already in them, the FFT dtype, the time slices the
    spectra are on instead of frequencies (None: on frequencies), and the threads imaging
    planes at once."""

    values: np.ndarray
    freqs: np.ndarray
    m: int
    geometry: CaptureGeometry
    coeffs: np.ndarray
    spectra: dict[tuple[int, ...], np.ndarray | None]
    weighted: bool
    cdtype: type
    slices: TimeSlices | None
    threads: int


class FFTImager(DeviceImager, PropagationImager[FFTImagerConfig]):
    """Fast RSD for planes parallel to the wall on a regular grid (both capture kinds)."""

    config_class = FFTImagerConfig
    imager_name = "fft"

    @classmethod
    def estimate_memory(cls, config: FFTImagerConfig, shape: PlanShape,
                        planes: int) -> MemoryEstimate:
        """The wall field's cached spectrum (every frequency on the padded lattice, at most
        half of ``chunk_mb``) and the threads' blocks of a few padded planes each (about
        :data:`_BLOCK_BYTES` for the kernels, their products and the sums), for voxel planes
        on the wall's grid."""
        ny, nx = shape.grid if shape.grid is not None else (
            (max(1, math.isqrt(max(1, shape.sensors))),) * 2)
        lattice = (scipy.fft.next_fast_len(max(1, 2 * int(ny) - 1))
                   * scipy.fft.next_fast_len(max(1, 2 * int(nx) - 1)))
        item = 8 if config.precision == "single" else 16
        spectrum = min(float(shape.frequencies * lattice * item), config.chunk_mb * 2**19)
        threads = min(worker_count(config.workers), max(1, planes))
        blocks = threads * 3.0 * max(_BLOCK_BYTES, 2 * lattice * item)
        return MemoryEstimate((
            MemoryPart("the field's spectrum", f"{shape.frequencies} frequencies on the "
                       f"padded {lattice}-point lattice, at most half of chunk_mb", spectrum),
            MemoryPart("the kernels' blocks", f"{threads} threads' blocks of padded planes",
                       blocks),
        ))

    # ------------------------------------------------------------------ checks
    def check_voxels(self, voxels: np.ndarray, field: PhasorField) -> np.ndarray:
        if voxels.ndim == 2:
            raise DataError(f"voxels: the fft imager needs planes parallel to the wall on a "
                            f"regular grid, (Y, X, 3) or (Z, Y, X, 3); got a point list "
                            f"{voxels.shape} (use the rsd imager for arbitrary points)")
        wall_layout(field)
        plane_layouts(voxels.reshape((-1,) + voxels.shape[-3:]))
        return voxels

    # ------------------------------------------------------------------ imaging
    def _intensity(self, field: PhasorField, voxels: np.ndarray, coeffs: np.ndarray,
                   on_progress: ProgressCallback | None = None) -> np.ndarray:
        if self.arrays is not None:
            return self._intensity_on(self.arrays, field, voxels, coeffs, on_progress)
        cfg = self.config
        cdtype = np.complex64 if cfg.precision == "single" else np.complex128
        wall = wall_layout(field)
        values = to_canonical(wall_field(field, cdtype), wall.order, axes=(1, 2))
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        cores = worker_count(cfg.workers)
        threads = min(cores, len(planes))                   # planes imaged in parallel
        fft_workers = max(1, cores // threads)              # the rest split each FFT
        fold = self._folds(field.geometry)
        layouts = [_plane(wall, plane, located, i, fft_workers, fold)
                   for i, (plane, located) in enumerate(zip(planes, plane_layouts(planes),
                                                           strict=True))]
        # coherent images of one virtual time: the coefficients go into the spectrum once,
        # and each block's sum over frequencies is a plain sum
        weighted = cfg.combine == "coherent" and coeffs.shape[0] == 1
        m = path_multiplier(field.geometry)
        slices = self._slices(field.frequencies, m, layouts) if weighted and fold else None
        volume = _Volume(values, field.frequencies, m, field.geometry, coeffs,
                         self._spectra(values, layouts, coeffs[0] if weighted else None,
                                       slices, cores),
                         weighted, cdtype, slices, threads)
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        progress = ProgressCounter(len(planes), on_progress)   # advanced from every thread

        def image(i: int) -> None:                  # planes write disjoint output slices
            layout = layouts[i]
            out[:, i] = from_canonical(self._image_plane(volume, layout), layout.order,
                                       axes=(1, 2))
            progress.advance()

        run_tasks(image, range(len(planes)), threads)
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _intensity_on(self, ops: ArrayOps, field: PhasorField, voxels: np.ndarray,
                      coeffs: np.ndarray, on_progress: ProgressCallback | None = None
                      ) -> np.ndarray:
        """:meth:`_intensity` on the device of ``ops``, plane by plane: every frequency's
        kernel on the plane's padded lattice, its FFT, the product with the wall field's
        spectrum and the sum over frequencies (before one inverse FFT for coherent
        confocal images, else after each frequency's, times the laser leg's phase)."""
        cdtype = np.complex64 if self.config.precision == "single" else np.complex128
        wall = wall_layout(field)
        values = to_canonical(wall_field(field, cdtype), wall.order, axes=(1, 2))
        planes = voxels.reshape((-1,) + voxels.shape[-3:])
        coherent = self.config.combine == "coherent"
        real = values.real.dtype.type
        volume = _DeviceVolume(ops, field.frequencies, path_multiplier(field.geometry),
                               ops.asarray(coeffs if coherent else np.abs(coeffs) ** 2,
                                           cdtype if coherent else real),
                               coherent, cdtype, self.config.chunk_mb)
        out = np.empty((coeffs.shape[0],) + planes.shape[:-1], dtype=np.float64)
        progress = ProgressCounter(len(planes), on_progress)
        spectra: dict[tuple[int, ...], DeviceArray] = {}
        for i, (plane, (grid, z)) in enumerate(zip(planes, plane_layouts(planes),
                                                   strict=True)):
            conv = PlaneConvolution(
                _axis(wall.shape[0], wall.spacing[0], grid.shape[0], grid.spacing[0],
                      grid.origin[0] - wall.origin[0], "y"),
                _axis(wall.shape[1], wall.spacing[1], grid.shape[1], grid.spacing[1],
                      grid.origin[1] - wall.origin[1], "x"), 1)
            if conv.input_key not in spectra:
                work = ops.zeros((values.shape[0],) + conv.shape, cdtype)
                work[(slice(None),) + conv.input_region] = ops.asarray(values)
                spectra[conv.input_key] = ops.fftn(work, conv.shape, (1, 2))
            r_l = laser_distances(to_canonical(plane, grid.order, axes=(0, 1)),
                                  field.geometry)
            image = _plane_on(volume, conv, spectra[conv.input_key], z, r_l)
            out[:, i] = from_canonical(image, grid.order, axes=(1, 2))
            progress.advance()
        return out.reshape((coeffs.shape[0],) + voxels.shape[:-1])

    def _metadata(self, field: PhasorField, voxels: np.ndarray) -> dict[str, object]:
        return {**super()._metadata(field, voxels), **self.device_info()}

    def _folds(self, geometry: CaptureGeometry) -> bool:
        """Whether frequencies are summed before a single inverse FFT per plane (coherent
        confocal images: no per-voxel phase)."""
        return self.config.combine == "coherent" and geometry.kind is CaptureKind.CONFOCAL

    def _slices(self, freqs: np.ndarray, m: int, layouts: list[_Plane]) -> TimeSlices | None:
        """The time slices of a coherent confocal image of one virtual time in single
        precision (:mod:`nlosfw.image.time_slices`) when the planes have on average at most
        :data:`_SLICES_PER_FREQUENCY` slices per frequency and their spectra fit in half of
        ``chunk_mb``; else None (every frequency's kernel is transformed)."""
        if self.config.precision != "single" or not layouts:
            return None
        bounds = np.array([layout.conv.distance_bounds(layout.z) for layout in layouts])
        grid = time_slices.time_slices(freqs, m, float(bounds.min()), float(bounds.max()))
        if grid is None:
            return None
        counts = [last - first + 1 for first, last in (grid.span(*b) for b in bounds)]
        if np.mean(counts) > _SLICES_PER_FREQUENCY * freqs.size:
            return None
        # the slices' spectra, and while they are computed a block of the frequencies'
        values = sum((grid.n + 2 * _SPECTRUM_BLOCK) * _spectrum_size(layout)
                     for layout in _distinct(layouts))
        if 8 * values > self.config.chunk_mb * 2**20 / 2:
            return None
        return grid

    def _spectra(self, values: np.ndarray, layouts: list[_Plane], weights: np.ndarray | None,
                 slices: TimeSlices | None, workers: int
                 ) -> dict[tuple[int, ...], np.ndarray | None]:
        """The wall field's spectrum per :attr:`_Plane.spectrum_key` (times ``weights`` per
        frequency when given; its four mirror images for an even kernel; on ``slices``
        instead of frequencies when given), None for those that do not fit in what is left
        of half of ``chunk_mb``; their FFTs on ``workers`` threads."""
        budget = self.config.chunk_mb * 2**20 / 2
        spectra: dict[tuple[int, ...], np.ndarray | None] = {}
        for layout in _distinct(layouts):
            nbytes = values.shape[0] * _spectrum_size(layout) * values.itemsize
            spectrum = None
            if slices is not None:
                spectrum = time_slices.time_spectra(
                    slices, _block_spectra(values, layout, weights, workers),
                    axis=2 if layout.folded else 0, block=_SPECTRUM_BLOCK, workers=workers)
            elif nbytes <= budget:
                spectrum = _spectrum(values, layout, weights, workers)
                budget -= nbytes
            spectra[layout.spectrum_key] = spectrum
        return spectra

    def _block_size(self, conv: PlaneConvolution, cdtype: type) -> int:
        """Frequencies per block: about 512 KiB of padded planes (they stay in the core's
        cache through the kernel, FFT, product and sum), within ``chunk_mb``."""
        plane_bytes = conv.shape[0] * conv.shape[1] * np.dtype(cdtype).itemsize
        cached = int(np.clip(_BLOCK_BYTES // plane_bytes, 2, 16))
        return max(1, min(cached, int(self.config.chunk_mb * 2**20 // (8 * plane_bytes))))

    def _rows_per_block(self, volume: _Volume, layout: _Plane) -> int:
        """Kernels transformed at once: :meth:`_block_size` frequencies, or all of the
        plane's time slices (one scatter of the kernel's samples) within the threads' share
        of the half of ``chunk_mb`` the spectra leave: per slice, its kernel and its DCT's
        real and imaginary parts on the quarter grid, or its kernel (transformed in place)
        and product on the full grid."""
        if volume.slices is None:
            return self._block_size(layout.conv, volume.cdtype)
        first, last = volume.slices.span(*layout.conv.distance_bounds(layout.z))
        ly, lx = layout.conv.shape
        values = 3 * (ly // 2 + 1) * (lx // 2 + 1) if layout.even else 2 * ly * lx
        share = self.config.chunk_mb * 2**20 / (2 * volume.threads)
        return max(1, min(last - first + 1,
                          int(share // (values * np.dtype(volume.cdtype).itemsize))))

    def _image_plane(self, volume: _Volume, layout: _Plane) -> np.ndarray:
        """Intensities (n_t, Y, X) of one plane, in canonical order."""
        if layout.folded:
            return self._image_even_plane(volume, layout)
        conv, freqs, coeffs, cdtype = layout.conv, volume.freqs, volume.coeffs, volume.cdtype
        size = self._rows_per_block(volume, layout)
        work = (np.zeros((size,) + even_kernel.quarter_shape(conv), dtype=cdtype)
                if layout.even else conv.padded(size, cdtype))
        kernels = work[(slice(None),) + (even_kernel.kernel_region(conv) if layout.even
                                         else conv.kernel_region)]
        products = conv.padded(size, cdtype) if layout.even else None
        spectrum = volume.spectra[layout.spectrum_key]
        fold = self._folds(volume.geometry)
        folded = np.zeros((coeffs.shape[0],) + conv.shape, dtype=cdtype) if fold else None
        amplitude: np.ndarray = np.zeros((conv.ay.n_out, conv.ax.n_out), dtype=cdtype)
        acc = FrequencySum(coeffs, self.config.combine, amplitude.shape)
        r_l = laser_distances(layout.voxels, volume.geometry)
        laser: np.ndarray | None = None
        blocks: Iterator[slice | np.ndarray]
        if r_l is None:
            blocks = _kernel_blocks(volume, layout, kernels)
        else:                                       # the laser leg's phasors, block by block
            laser = np.empty((work.shape[0],) + r_l.shape, dtype=cdtype)
            blocks = _same_blocks(kernel_blocks(freqs, layout.distances(), volume.m, kernels),
                                  phasor_blocks(freqs, r_l, laser))
        for sel in blocks:
            k = _count(sel)
            rows = (spectrum[sel] if spectrum is not None
                    else _spectrum(volume.values[sel], layout,
                                   coeffs[0, sel] if volume.weighted else None))
            if products is not None:                # an even kernel: its quarter's DCT
                block = even_kernel.multiply(rows, even_kernel.kernel_spectrum(
                    work[:k], conv.workers), out=products[:k])
                even_kernel.clear_padding(conv, work)
            else:                                   # the FFT overwrites the kernels
                block = scipy.fft.fft2(work[:k], overwrite_x=True, workers=conv.workers)
                block *= rows
            if folded is None:
                fields = (even_kernel.read_outputs(conv, block) if layout.even
                          else conv.read_outputs(block))
                if laser is not None:
                    fields *= laser[:k]
                if volume.weighted:
                    amplitude += fields.sum(axis=0)
                else:
                    acc.add(fields, sel)
            elif volume.weighted:
                folded[0] += block.sum(axis=0)
            else:
                folded += np.einsum("tf,fyx->tyx", coeffs[:, sel].astype(cdtype), block)
            if products is None:
                conv.clear_padding(work)
        if folded is not None:
            acc.add_amplitude(conv.read_outputs(folded))
        elif volume.weighted:
            acc.add_amplitude(amplitude[None])
        return acc.intensity()

    def _image_even_plane(self, volume: _Volume, layout: _Plane) -> np.ndarray:
        """Intensities (n_t, Y, X) of one plane whose frequencies fold on an even kernel:
        the sum over frequencies on the quarter grid, once per mirror image of the
        spectrum, then one full inverse FFT (:mod:`nlosfw.image.even_kernel`)."""
        conv, coeffs, cdtype = layout.conv, volume.coeffs, volume.cdtype
        quarter = even_kernel.quarter_shape(conv)
        work = np.zeros((self._rows_per_block(volume, layout),) + quarter, dtype=cdtype)
        kernels = work[(slice(None),) + even_kernel.kernel_region(conv)]
        spectrum = volume.spectra[layout.spectrum_key]
        sums = np.zeros((2, 2, coeffs.shape[0]) + quarter, dtype=cdtype)
        step = min(work.shape[0], _PRODUCT_ROWS)          # products in cache-sized parts
        products = np.empty((2, 2, step) + quarter, dtype=cdtype)
        rows: np.ndarray = coeffs.astype(cdtype)
        for sel in _kernel_blocks(volume, layout, kernels):
            k = _count(sel)
            block = even_kernel.kernel_spectrum(work[:k], conv.workers)
            images = (spectrum[:, :, sel] if spectrum is not None
                      else _spectrum(volume.values[sel], layout,
                                     coeffs[0, sel] if volume.weighted else None))
            for a in range(0, k, step):
                b = min(k, a + step)
                product = np.multiply(images[:, :, a:b], block[a:b],
                                      out=products[:, :, :b - a])  # (2, 2, b - a, hy, hx)
                if volume.weighted:
                    sums[:, :, 0] += product.sum(axis=2)
                else:
                    sums += np.einsum("tf,abfyx->abtyx", rows[:, sel][:, a:b], product)
            even_kernel.clear_padding(conv, work)
        acc = FrequencySum(coeffs, self.config.combine, (conv.ay.n_out, conv.ax.n_out))
        acc.add_amplitude(even_kernel.read_outputs(conv, even_kernel.assemble(sums)))
        return acc.intensity()


@dataclass(frozen=True, eq=False)
class _DeviceVolume:
    """What every plane imaged on a device shares: the array backend, the frequencies, the
    path multiplier, the coefficient rows c[t, f] on the device (|c|^2 for incoherent
    images), the combination, the complex dtype and the memory budget (MiB)."""

    ops: ArrayOps
    freqs: np.ndarray
    m: int
    rows: DeviceArray
    coherent: bool
    cdtype: type
    chunk_mb: float

    def block(self, conv: PlaneConvolution) -> int:
        """Frequencies per block: four padded planes each (kernel, spectrum, product,
        inverse) within ``chunk_mb``."""
        plane_bytes = conv.shape[0] * conv.shape[1] * np.dtype(self.cdtype).itemsize
        return max(1, int(self.chunk_mb * 2**20 // (4 * plane_bytes)))


def _plane_on(volume: _DeviceVolume, conv: PlaneConvolution, spectrum: DeviceArray, z: float,
              r_l: np.ndarray | None) -> np.ndarray:
    """Intensities (n_t, Y, X) of the plane at depth ``z`` in canonical order, on the
    volume's device: ``spectrum`` the wall field's (F, L_y, L_x) there, ``r_l`` the
    voxels' laser distances (None: confocal, whose coherent images sum the frequencies
    before one inverse FFT)."""
    ops, cdtype, freqs = volume.ops, volume.cdtype, volume.freqs
    r = conv.distances(z)
    path = ops.asarray(volume.m * r, np.float64)
    scale = ops.asarray(1.0 / r, cdtype)
    laser = None if r_l is None else ops.asarray(r_l, np.float64)
    outputs = (slice(None),) + conv.output_region
    fold = volume.coherent and r_l is None
    rows = volume.rows
    acc = ops.zeros((rows.shape[0],) + (conv.shape if fold else (conv.ay.n_out, conv.ax.n_out)),
                    cdtype if volume.coherent else _REAL[cdtype])
    block = volume.block(conv)
    for start in range(0, freqs.size, block):
        sel = slice(start, min(freqs.size, start + block))
        f = ops.asarray(freqs[sel], np.float64)[:, None, None]
        kernels = ops.zeros((sel.stop - start,) + conv.shape, cdtype)
        kernels[(slice(None),) + conv.kernel_region] = ops.phasor(f * path, cdtype) * scale
        product = ops.fftn(kernels, conv.shape, (1, 2)) * spectrum[sel]
        del kernels
        if fold:
            acc += ops.einsum("tf,fyx->tyx", rows[:, sel], product)
            continue
        fields = ops.ifftn(product, (1, 2))[outputs]
        if laser is not None:
            fields = fields * ops.phasor(f * laser, cdtype)
        if volume.coherent:
            acc += ops.einsum("tf,fyx->tyx", rows[:, sel], fields)
        else:
            acc += ops.einsum("tf,fyx->tyx", rows[:, sel], fields.real ** 2 + fields.imag ** 2)
    if fold:
        acc = ops.ifftn(acc, (1, 2))[outputs]
    image = acc.real ** 2 + acc.imag ** 2 if volume.coherent else acc
    return ops.numpy(image).astype(np.float64)


def _kernel_blocks(volume: _Volume, layout: _Plane, kernels: np.ndarray
                   ) -> Iterator[slice | np.ndarray]:
    """The plane's kernels into ``kernels`` block by block: per frequency
    (:func:`~nlosfw.image.rsd_kernel.kernel_blocks`) or per time slice
    (:meth:`~nlosfw.image.time_slices.TimeSlices.kernel_blocks`); yields the rows of the
    volume's spectra they go with."""
    if volume.slices is not None:
        return volume.slices.kernel_blocks(layout.distances(), kernels)
    return kernel_blocks(volume.freqs, layout.distances(), volume.m, kernels)


def _count(rows: slice | np.ndarray) -> int:
    """Rows in a block (:func:`_kernel_blocks`)."""
    return rows.stop - rows.start if isinstance(rows, slice) else int(rows.size)


def _distinct(layouts: list[_Plane]) -> list[_Plane]:
    """The first plane of each :attr:`_Plane.spectrum_key`."""
    return list({layout.spectrum_key: layout for layout in reversed(layouts)}.values())[::-1]


def _spectrum_size(layout: _Plane) -> int:
    """Values per frequency of the plane's spectrum (four mirror images for an even
    kernel)."""
    ly, lx = layout.conv.shape
    return 4 * (ly // 2 + 1) * (lx // 2 + 1) if layout.folded else ly * lx


def _spectrum(values: np.ndarray, layout: _Plane, weights: np.ndarray | None,
              workers: int | None = None) -> np.ndarray:
    """The spectrum of wall fields (F, Y, X) on the plane's layout, times ``weights`` (F,)
    when given; its four mirror images (2, 2, F, hy, hx) when the plane is folded; its FFTs
    on ``workers`` threads (None: the layout's)."""
    spectrum = layout.conv.input_spectrum(values, workers)
    if weights is not None:
        spectrum *= weights.astype(values.dtype)[:, None, None]
    return even_kernel.quarters(spectrum) if layout.folded else spectrum


def _block_spectra(values: np.ndarray, layout: _Plane, weights: np.ndarray | None,
                   workers: int) -> Callable[[slice], np.ndarray]:
    """:func:`_spectrum` of the frequencies ``sel``, as a function of ``sel``."""
    def spectra(sel: slice) -> np.ndarray:
        return _spectrum(values[sel], layout, None if weights is None else weights[sel],
                         workers)

    return spectra


def _plane(wall: GridLayout, plane: np.ndarray, located: tuple[GridLayout, float],
           index: int, workers: int, fold: bool) -> _Plane:
    """The layout of voxel plane ``index`` (its grid and depth ``located``:
    :func:`plane_layouts`) against the wall (DataError for a spacing the FFT convolution
    cannot take); ``fold``: frequencies are summed before the inverse FFT."""
    grid, z = located
    ay = _axis(wall.shape[0], wall.spacing[0], grid.shape[0], grid.spacing[0],
               grid.origin[0] - wall.origin[0], "y")
    ax = _axis(wall.shape[1], wall.spacing[1], grid.shape[1], grid.spacing[1],
               grid.origin[1] - wall.origin[1], "x")
    even = even_kernel.even_layout(ay, ax, workers)
    conv = even if even is not None else PlaneConvolution(ay, ax, workers)
    return _Plane(to_canonical(plane, grid.order, axes=(0, 1)), grid.order, z, conv,
                  even is not None, even is not None and fold)


def _same_blocks(first: Iterator[slice], second: Iterator[slice]) -> Iterator[slice]:
    """Advance two block generators over the same frequencies together."""
    for a, b in zip(first, second, strict=True):
        if a != b:
            raise RuntimeError(f"block generators out of step: {a} and {b}")
        yield a


#: The real dtype of each complex dtype.
_REAL: dict[type, type] = {np.complex64: np.float32, np.complex128: np.float64}
#: Target bytes of one block of padded frequency planes (per thread).
_BLOCK_BYTES = 2**19
#: Time slices are used when the planes have on average at most this many per frequency.
_SLICES_PER_FREQUENCY = 0.75
#: Kernels multiplied with the spectrum's four mirror images at once (a few hundred KiB).
_PRODUCT_ROWS = 8
#: Frequencies whose spectra are computed at once for the time slices' spectra.
_SPECTRUM_BLOCK = 16


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

"""The plane convolution of an even kernel: its spectrum from a quarter of the work.

When a voxel plane is the wall's own grid seen at depth z (no offset between the two
lattices and the same extent along each axis, the usual volume of a run), the kernel
h(u) = exp(2 pi i f m r(u)) / r(u) of :mod:`nlosfw.image.plane_convolution` depends on
the lattice offset u only through |u| per axis: it is even. Placed circularly (offset u
at index u mod L, L even and at least the linear convolution's length) its DFT is even
too, H[k] = H[L - k] per axis, and the unique quarter k in [0, L/2] per axis is the
type-I DCT of the kernel's quarter u in [0, L/2] (scipy's ``dctn(type=1)``, exactly):
half the transform work of a full FFT, on a quarter of the samples.

The ``fft`` imager uses it for coherent confocal images, where the product with the
field's spectrum S is summed over frequencies before one inverse FFT: the sum
Q(k) = sum_f S_f(k) H_f(k) is evaluated on the quarter grid once per mirror image of S
(:func:`quarters`, four per plane for two axes) and the full Q assembled once per plane
(:func:`assemble`). The input sits where :class:`PlaneConvolution` puts it (the
field's spectrum is shared), the output is read from index 0 (:func:`read_outputs`).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from nlosfw.image.plane_convolution import LatticeAxis, PlaneConvolution, read_points

#: Largest |offset| between the two lattices, relative to the lattice step, taken as 0.
OFFSET_RTOL = 1e-9


def is_even(conv: PlaneConvolution) -> bool:
    """Whether the layout's kernel is even with an even padded length on both axes."""
    return all(symmetric(axis) and length % 2 == 0
               for axis, length in zip((conv.ay, conv.ax), conv.shape, strict=True))


def symmetric(axis: LatticeAxis) -> bool:
    """Whether the kernel is even along this axis: both grids span the same lattice points
    (same extent, no offset; more than one point)."""
    return (axis.n_in_lattice == axis.n_out_lattice > 1
            and abs(axis.offset) <= OFFSET_RTOL * axis.step)


def even_layout(ay: LatticeAxis, ax: LatticeAxis, workers: int) -> PlaneConvolution | None:
    """The layout padded to even fast lengths when the kernel is even along both axes
    (then :func:`is_even`), else None."""
    if not (symmetric(ay) and symmetric(ax)):
        return None
    return PlaneConvolution(ay, ax, workers, shape=(_even_fast_length(ay.n_linear),
                                                    _even_fast_length(ax.n_linear)))


def _even_fast_length(n: int) -> int:
    """The smallest even length >= n that scipy's FFT handles fast (2 x a fast length)."""
    return 2 * scipy.fft.next_fast_len((n + 1) // 2)


def quarter_shape(conv: PlaneConvolution) -> tuple[int, int]:
    """(L_y / 2 + 1, L_x / 2 + 1): the unique quarter of an even spectrum."""
    return conv.shape[0] // 2 + 1, conv.shape[1] // 2 + 1


def kernel_region(conv: PlaneConvolution) -> tuple[slice, slice]:
    """Where the kernel's samples u = 0 ... n_lattice - 1 go on the quarter grid (the rest
    of the quarter is zero)."""
    return slice(0, conv.ay.n_in_lattice), slice(0, conv.ax.n_in_lattice)


def distances(conv: PlaneConvolution, z: float) -> np.ndarray:
    """|x_o - x_i| on :func:`kernel_region` for a plane at distance ``z``."""
    dy = conv.ay.step * np.arange(conv.ay.n_in_lattice)
    dx = conv.ax.step * np.arange(conv.ax.n_in_lattice)
    return np.sqrt(dy[:, None] ** 2 + dx[None, :] ** 2 + z * z)


def kernel_spectrum(kernels: np.ndarray, workers: int) -> np.ndarray:
    """The quarter spectra (batch, hy, hx) of even kernels given by their quarter
    (batch, hy, hx), zero beyond the kernel region (may overwrite ``kernels``)."""
    return scipy.fft.dctn(kernels, type=1, axes=(-2, -1), overwrite_x=True, workers=workers)


def clear_padding(conv: PlaneConvolution, work: np.ndarray) -> None:
    """Zero a quarter-grid array (batch, hy, hx) outside the kernel region, in place."""
    ny, nx = conv.ay.n_in_lattice, conv.ax.n_in_lattice
    work[:, ny:, :] = 0
    work[:, :ny, nx:] = 0


def quarters(spectra: np.ndarray) -> np.ndarray:
    """The four mirror images (2, 2, *batch, hy, hx) of full spectra (*batch, L_y, L_x) on
    the quarter grid: image (a, b) holds, at quarter index (p, q), the value at full index
    (p if a == 0 else L_y - p, q if b == 0 else L_x - q); zeros where that index is not
    one of the image's own (a mirror image never repeats a full index)."""
    ly, lx = spectra.shape[-2:]
    hy, hx = ly // 2 + 1, lx // 2 + 1
    out = np.zeros((2, 2) + spectra.shape[:-2] + (hy, hx), dtype=spectra.dtype)
    rows = (slice(0, hy), slice(ly - 1, ly // 2, -1))         # p, and L_y - p for p >= 1
    cols = (slice(0, hx), slice(lx - 1, lx // 2, -1))
    own_rows = (slice(0, hy), slice(1, hy - 1))
    own_cols = (slice(0, hx), slice(1, hx - 1))
    for a in range(2):
        for b in range(2):
            out[a, b, ..., own_rows[a], own_cols[b]] = spectra[..., rows[a], cols[b]]
    return out


def assemble(sums: np.ndarray) -> np.ndarray:
    """Full arrays (*batch, L_y, L_x) from values on the four mirror images (2, 2, *batch,
    hy, hx) (the inverse of :func:`quarters` for the indices each image owns)."""
    rows = [_join(sums[a, 0], sums[a, 1], sums.ndim - 3) for a in range(2)]
    return _join(rows[0], rows[1], rows[0].ndim - 2)


def read_outputs(conv: PlaneConvolution, product: np.ndarray) -> np.ndarray:
    """Inverse FFT of full products (batch, L_y, L_x), read at the output points (from
    index 0: the kernel's offset 0 sits at index 0; may overwrite ``product``)."""
    return read_points(product, (slice(0, conv.ay.n_out_lattice, conv.ay.stride_out),
                                 slice(0, conv.ax.n_out_lattice, conv.ax.stride_out)),
                       conv.workers)


def multiply(spectra: np.ndarray, quarter: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out`` = full spectra (batch, L_y, L_x) times the even spectra whose quarter
    (batch, hy, hx) is given (:func:`kernel_spectrum`): the quarter mirrored into ``out``,
    then one product."""
    ly, lx = spectra.shape[-2:]
    hy, hx = ly // 2 + 1, lx // 2 + 1
    out[..., :hy, :hx] = quarter
    out[..., :hy, hx:] = quarter[..., hx - 2:0:-1]                  # columns L_x - q
    out[..., hy:, :] = out[..., hy - 2:0:-1, :]                      # rows L_y - p
    return np.multiply(out, spectra, out=out)


def _join(direct: np.ndarray, mirrored: np.ndarray, axis: int) -> np.ndarray:
    """The full axis (L) from its indices 0 ... L/2 (``direct``) and the mirror image
    ``mirrored`` holding L - p at p = 1 ... L/2 - 1 (zeros at p = 0 and L/2)."""
    half = direct.shape[axis] - 1
    tail = np.take(mirrored, np.arange(half - 1, 0, -1), axis=axis)     # L/2 + 1 ... L - 1
    return np.concatenate([direct, tail], axis=axis)

"""FFT convolution between two parallel regular grids: the wall (z = 0) and a voxel plane.

Both grids are regular and axis-aligned, and along each axis both spacings are whole
multiples of one *lattice* step s (one grid's spacing divides the other's). A sum

    out(o) = sum_i in(i) h(x_o - x_i)

from one grid to the other is then a linear convolution on the lattice: the input is
placed every ``stride_in`` lattice points (zeros between), the kernel h is sampled at
every lattice offset x_o - x_i that occurs, both are zero-padded to a fast FFT length of
at least n_in + n_out - 1 lattice points per axis (so the convolution is linear, not
circular), multiplied in the Fourier domain, and the output read every ``stride_out``
lattice points. The adjoint, in(i) = sum_o out(o) conj(h(x_o - x_i)), uses the same
layout: scatter at the output positions, multiply by conj(FFT(h)), read at the input
positions. Cost per plane and frequency: O(N^2 log N) instead of O(N^4).

The ``fft`` imager convolves the wall field into voxel planes (input: wall, output:
voxels); the ``rsd_prior`` field model propagates voxel planes to the wall and back
(input: voxels, output: wall). Grids may come in any orientation (x along either array
axis, increasing or decreasing): :func:`grid_layout` finds the canonical order (x along
axis 1, y along axis 0, both increasing) and :func:`to_canonical` /
:func:`from_canonical` move arrays in and out of it. :func:`wall_layout`,
:func:`plane_layout` and :func:`plane_layouts` (a volume's) are the imagers' checked
versions (the ``fft`` imager and the classical ``lct``/``fk``/``fbp`` imagers of
:mod:`nlosfw.image.transient`): a one-line DataError for a wall or voxel plane that is not
such a grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.fft

from nlosfw.common.errors import DataError
from nlosfw.transform.field import PhasorField, regular_grid_spacing

#: Relative tolerance on "one spacing is a whole multiple of the other".
RATIO_RTOL = 1e-3
#: Relative tolerance on the flatness of a voxel plane (constant z).
FLATNESS_RTOL = 1e-6


class GridOrder(NamedTuple):
    """(transpose, flip rows, flip columns) that bring a grid into canonical order."""

    transpose: bool
    flip_rows: bool
    flip_cols: bool


@dataclass(frozen=True)
class GridLayout:
    """A regular grid in canonical order: its reordering, first point and spacing."""

    order: GridOrder
    origin: tuple[float, float]
    """(y0, x0) of the first point in canonical order."""
    spacing: tuple[float, float]
    """(dy, dx); 0 along an axis with a single point."""
    shape: tuple[int, int]
    """(ny, nx) in canonical order."""


def grid_order(points: np.ndarray) -> GridOrder:
    """The reordering that makes x run along axis 1 and y along axis 0, both increasing
    (a single row or column is oriented by its one varying coordinate)."""
    p = points
    transpose = False
    if p.shape[0] > 1 and p.shape[1] > 1:
        along0 = np.abs(p[1, 0, :2] - p[0, 0, :2])
        transpose = bool(along0[0] > along0[1])
    elif p.shape[0] > 1:
        transpose = bool(abs(p[1, 0, 0] - p[0, 0, 0]) > abs(p[1, 0, 1] - p[0, 0, 1]))
    elif p.shape[1] > 1:
        transpose = bool(abs(p[0, 1, 1] - p[0, 0, 1]) > abs(p[0, 1, 0] - p[0, 0, 0]))
    q = p.transpose(1, 0, 2) if transpose else p
    flip_rows = q.shape[0] > 1 and q[-1, 0, 1] < q[0, 0, 1]
    flip_cols = q.shape[1] > 1 and q[0, -1, 0] < q[0, 0, 0]
    return GridOrder(transpose, bool(flip_rows), bool(flip_cols))


def to_canonical(a: np.ndarray, order: GridOrder, axes: tuple[int, int]) -> np.ndarray:
    """An array laid out like the grid (its grid axes ``axes``), in canonical order (a view)."""
    if order.transpose:
        a = np.swapaxes(a, *axes)
    if order.flip_rows:
        a = np.flip(a, axis=axes[0])
    if order.flip_cols:
        a = np.flip(a, axis=axes[1])
    return a


def from_canonical(a: np.ndarray, order: GridOrder, axes: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`to_canonical`."""
    if order.flip_cols:
        a = np.flip(a, axis=axes[1])
    if order.flip_rows:
        a = np.flip(a, axis=axes[0])
    if order.transpose:
        a = np.swapaxes(a, *axes)
    return a


def grid_layout(points: np.ndarray) -> GridLayout | None:
    """The canonical layout of points (Y, X, 3) forming a regular axis-aligned grid in the
    plane z = 0, or of (Y, X, 2) wall coordinates; None when they do not."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 3 or p.shape[-1] not in (2, 3):
        return None
    if p.shape[-1] == 2:
        p = np.concatenate([p, np.zeros(p.shape[:2] + (1,))], axis=-1)
    order = grid_order(p)
    canon = to_canonical(p, order, axes=(0, 1))
    spacing = regular_grid_spacing(canon)
    if spacing is None:
        return None
    return GridLayout(order, (float(canon[0, 0, 1]), float(canon[0, 0, 0])), spacing,
                      (int(canon.shape[0]), int(canon.shape[1])))


def wall_layout(field: PhasorField) -> GridLayout:
    """The canonical layout of the field's wall; DataError unless it is a regular grid."""
    layout = grid_layout(field.wall_xyz)
    if layout is None:
        raise DataError("field.wall_xyz: the imager needs the field on a regular, "
                        "axis-aligned wall grid in the plane z = 0; use the rsd imager for "
                        "other walls")
    return layout


def plane_layout(plane: np.ndarray, index: int) -> tuple[GridLayout, float]:
    """(canonical layout, depth z) of voxel plane ``index`` (Y, X, 3); DataError unless it
    is a regular x-y grid parallel to the wall."""
    z = _depth(plane[..., 2], float(np.ptp(plane[..., :2])), index)
    return _grid(plane, index), z


def plane_layouts(planes: np.ndarray) -> list[tuple[GridLayout, float]]:
    """:func:`plane_layout` of every plane of ``planes`` (Z, Y, X, 3); when all of them
    have the first one's x-y points (a volume of depth planes) its grid is checked once."""
    if planes.shape[0] < 2 or not np.array_equal(planes[1:, ..., :2], np.broadcast_to(
            planes[:1, ..., :2], planes[1:, ..., :2].shape)):
        return [plane_layout(plane, i) for i, plane in enumerate(planes)]
    first, _ = plane_layout(planes[0], 0)
    extent = float(np.ptp(planes[0, ..., :2]))
    z = planes[..., 2]
    low, high = z.min(axis=(1, 2)), z.max(axis=(1, 2))
    scale = np.maximum(np.maximum(np.abs(low), np.abs(high)), max(1.0, extent))
    for i in np.flatnonzero(high - low > FLATNESS_RTOL * scale):
        _depth(z[i], extent, int(i))                                # the error of plane i
    return [(first, float(depth)) for depth in z.mean(axis=(1, 2))]


def _depth(z: np.ndarray, extent: float, index: int) -> float:
    """The depth of voxel plane ``index`` from its z (Y, X) and the extent of its x-y
    points; DataError unless it is flat."""
    scale = max(1.0, float(np.abs(z).max()), extent)
    if np.ptp(z) > FLATNESS_RTOL * scale:
        raise DataError(f"voxels: plane {index} is not parallel to the wall (z from "
                        f"{z.min():.6g} to {z.max():.6g} m); the imager needs planes of "
                        "constant z on a regular x-y grid; use the rsd imager for other voxels")
    return float(z.mean())


def _grid(plane: np.ndarray, index: int) -> GridLayout:
    """The canonical layout of voxel plane ``index``'s x-y points; DataError unless they
    form a regular axis-aligned grid."""
    layout = grid_layout(plane[..., :2])
    if layout is None:
        raise DataError(f"voxels: plane {index} is not a regular axis-aligned x-y grid; the "
                        "imager needs regularly spaced planes parallel to the wall; use the "
                        "rsd imager for other voxels")
    return layout


@dataclass(frozen=True)
class LatticeAxis:
    """One axis of a convolution from ``n_in`` to ``n_out`` points on a common lattice.

    Input point i sits at lattice index ``stride_in * i``, output point o at
    ``n_in_lattice - 1 + stride_out * o`` of the linear convolution; ``offset`` is the
    first output coordinate minus the first input coordinate.
    """

    n_in: int
    stride_in: int
    n_out: int
    stride_out: int
    step: float
    offset: float

    @property
    def n_in_lattice(self) -> int:
        return self.stride_in * (self.n_in - 1) + 1

    @property
    def n_out_lattice(self) -> int:
        return self.stride_out * (self.n_out - 1) + 1

    @property
    def n_linear(self) -> int:
        """Length of the linear convolution (the kernel samples)."""
        return self.n_in_lattice + self.n_out_lattice - 1

    @property
    def inputs(self) -> slice:
        """Where the input points sit on the padded lattice."""
        return slice(0, self.n_in_lattice, self.stride_in)

    @property
    def outputs(self) -> slice:
        """Where the output points are read on the padded lattice."""
        start = self.n_in_lattice - 1
        return slice(start, start + self.n_out_lattice, self.stride_out)

    def offsets(self) -> np.ndarray:
        """Output - input coordinate differences sampled by the kernel (``n_linear``)."""
        return self.offset + self.step * (np.arange(self.n_linear) - (self.n_in_lattice - 1))


def lattice_axis(n_in: int, in_step: float, n_out: int, out_step: float,
                 offset: float) -> LatticeAxis | None:
    """The common lattice of two regular axes, or None unless one step is a whole
    multiple of the other (an axis with one point fits any lattice)."""
    if n_in == 1 and n_out == 1:
        return LatticeAxis(1, 1, 1, 1, 1.0, offset)
    if n_in == 1:
        return LatticeAxis(1, 1, n_out, 1, out_step, offset)
    if n_out == 1:
        return LatticeAxis(n_in, 1, 1, 1, in_step, offset)
    fine, coarse = sorted((in_step, out_step))
    ratio = coarse / fine
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > RATIO_RTOL * ratio:
        return None
    step = coarse / k
    if in_step >= out_step:
        return LatticeAxis(n_in, k, n_out, 1, step, offset)
    return LatticeAxis(n_in, 1, n_out, k, step, offset)


class PlaneConvolution:
    """The FFT layout of convolutions between two grids on one lattice (see module doc).

    Arrays of input values are (batch, n_in_y, n_in_x), of output values
    (batch, n_out_y, n_out_x); kernels are sampled on (n_linear_y, n_linear_x).
    """

    def __init__(self, ay: LatticeAxis, ax: LatticeAxis, workers: int = -1,
                 shape: tuple[int, int] | None = None) -> None:
        self.ay, self.ax = ay, ax
        self.workers = workers
        if shape is None:
            shape = (scipy.fft.next_fast_len(ay.n_linear), scipy.fft.next_fast_len(ax.n_linear))
        if shape[0] < ay.n_linear or shape[1] < ax.n_linear:
            raise ValueError(f"padded shape {shape} is shorter than the linear convolution "
                             f"({ay.n_linear}, {ax.n_linear})")
        self.shape = (int(shape[0]), int(shape[1]))
        """Padded lengths (L_y, L_x): by default the next fast lengths of the linear
        convolution."""

    @property
    def kernel_region(self) -> tuple[slice, slice]:
        """Where the kernel samples go in a padded array."""
        return slice(0, self.ay.n_linear), slice(0, self.ax.n_linear)

    @property
    def input_region(self) -> tuple[slice, slice]:
        return self.ay.inputs, self.ax.inputs

    @property
    def output_region(self) -> tuple[slice, slice]:
        return self.ay.outputs, self.ax.outputs

    @property
    def input_key(self) -> tuple[int, ...]:
        """Equal for layouts whose input spectra are equal (for caching them)."""
        return (self.ay.stride_in, self.ax.stride_in, self.ay.n_in, self.ax.n_in) + self.shape

    def distances(self, z: float) -> np.ndarray:
        """|x_o - x_i| for a plane at distance ``z`` from the other, on the kernel samples."""
        dy, dx = self.ay.offsets(), self.ax.offsets()
        return np.sqrt(dy[:, None] ** 2 + dx[None, :] ** 2 + z * z)

    def distance_bounds(self, z: float) -> tuple[float, float]:
        """(smallest, largest) of :meth:`distances` ``(z)``."""
        dy, dx = np.abs(self.ay.offsets()), np.abs(self.ax.offsets())
        return (float(np.sqrt(dy.min() ** 2 + dx.min() ** 2 + z * z)),
                float(np.sqrt(dy.max() ** 2 + dx.max() ** 2 + z * z)))

    def padded(self, batch: int, dtype: type) -> np.ndarray:
        """A zeroed padded array (batch, *shape)."""
        return np.zeros((batch,) + self.shape, dtype=dtype)

    def clear_padding(self, work: np.ndarray) -> None:
        """Zero a padded array (batch, *shape) outside the kernel region, in place (an
        in-place FFT of the previous kernels wrote there)."""
        ly, lx = self.ay.n_linear, self.ax.n_linear
        work[:, ly:, :] = 0
        work[:, :ly, lx:] = 0

    def kernel_spectrum(self, kernels: np.ndarray, dtype: type) -> np.ndarray:
        """FFT of kernels (batch, n_linear_y, n_linear_x) zero-padded to ``shape``."""
        work = self.padded(kernels.shape[0], dtype)
        work[(slice(None),) + self.kernel_region] = kernels
        return scipy.fft.fft2(work, overwrite_x=True, workers=self.workers)

    def input_spectrum(self, values: np.ndarray, workers: int | None = None) -> np.ndarray:
        """FFT of input values (batch, n_in_y, n_in_x) placed on the padded lattice (on
        ``workers`` threads; None: the layout's)."""
        work = self.padded(values.shape[0], values.dtype.type)
        work[(slice(None),) + self.input_region] = values
        return scipy.fft.fft2(work, overwrite_x=True, workers=workers or self.workers)

    def output_spectrum(self, values: np.ndarray) -> np.ndarray:
        """FFT of output-side values (batch, n_out_y, n_out_x) placed at the output
        positions (the first step of the adjoint)."""
        work = self.padded(values.shape[0], values.dtype.type)
        work[(slice(None),) + self.output_region] = values
        return scipy.fft.fft2(work, overwrite_x=True, workers=self.workers)

    def read_outputs(self, product: np.ndarray) -> np.ndarray:
        """Inverse FFT of spectrum products (batch, *shape), read at the output points (may
        overwrite ``product``)."""
        return read_points(product, self.output_region, self.workers)

    def read_inputs(self, product: np.ndarray, workers: int | None = None) -> np.ndarray:
        """Inverse FFT of (conjugate-kernel) products, read at the input points (adjoint;
        on ``workers`` threads, None: the layout's; may overwrite ``product``)."""
        return read_points(product, self.input_region, workers or self.workers)


def read_points(spectra: np.ndarray, region: tuple[slice, slice], workers: int) -> np.ndarray:
    """The inverse 2-D FFT of ``spectra`` (batch, L_y, L_x) at the points ``region`` (rows,
    columns) only: along y, then along x on the rows read alone (may overwrite
    ``spectra``)."""
    rows = scipy.fft.ifft(spectra, axis=-2, overwrite_x=True, workers=workers)[..., region[0], :]
    return scipy.fft.ifft(rows, axis=-1, overwrite_x=True, workers=workers)[..., region[1]]

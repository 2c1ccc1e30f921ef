"""The physics of the ``rsd_prior`` field model: voxel albedo -> wall phasor fields.

A hidden scene is a non-negative albedo a_v on voxels in planes parallel to the wall,
the same at every frequency. With the transform's sign (a scatterer at path d gives
P ∝ e^{-2 pi i f d}, see :mod:`nlosfw.image.rsd_kernel`) its wall field is

    single spot:  P_f(x_s) = sum_v a_v g(r_l) g(r_s) exp(-2 pi i f (r_l + r_s))
    confocal:     P_f(x_s) = sum_v a_v g(r_s)^2      exp(-2 pi i f 2 r_s)

with r_l = |x_v - x_l|, r_s = |x_v - x_s|, z the voxel's depth and g the amplitude of
one leg (:class:`Amplitude`; constants such as 1/pi^3 are absorbed in the albedo):

* ``lambertian``: g = z^2 / r^4 = cos(wall) cos(voxel) / r^2, a surface element facing
  the wall, the convention of :mod:`nlosfw.simulate.physics`; with a glossy lobe of
  exponent k (``OperatorOptions.lobe``) times cos(voxel)^(k/2) per leg: the simulators'
  cos^k of the half vector's angle exactly for a confocal scan, approximately (the
  product of the legs' half-powers) for a single spot;
* ``point``: g = z / r^3 = cos(wall) / r^2, a point scatterer of the same convention;
* ``inverse_square``: g = 1 / r^2 (no cosines).

Per plane the sum over voxels is a convolution (the sensor leg depends on x_s - x_v
only) times a per-voxel laser leg L_f(x_v) = g(r_l) e^{-2 pi i f r_l}, evaluated by the
FFT layout of :mod:`nlosfw.image.plane_convolution` (one layout shared with the ``fft``
imager; also for voxels coarser than the wall) with the kernels of
:func:`nlosfw.image.rsd_kernel.phasor_series`. The adjoint is the correlation with the
conjugate kernels, i.e. an RSD back-propagation: the ``fft`` imager's sum with this
model's amplitudes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.config import Choice
from nlosfw.common.cores import run_tasks, worker_count
from nlosfw.common.errors import DataError
from nlosfw.image.plane_convolution import GridLayout, PlaneConvolution, lattice_axis
from nlosfw.image.rsd_kernel import path_multiplier, phasor_series, phasor_steps


class Amplitude(Choice):
    """Amplitude of one leg of the three-bounce path (see the module docstring)."""

    lambertian = "lambertian"
    point = "point"
    inverse_square = "inverse_square"


def leg_amplitude(r: np.ndarray, z: float | np.ndarray, amplitude: str,
                  lobe: float = 0.0) -> np.ndarray:
    """g(r, z) of one leg: lambertian z^2/r^4 (times (z/r)^(lobe/2) for a glossy lobe),
    point z/r^3, inverse_square 1/r^2."""
    r = np.asarray(r, dtype=float)
    if amplitude == Amplitude.lambertian:
        g = np.asarray(z) ** 2 / r**4
        return g if lobe == 0 else g * (np.asarray(z) / r) ** (lobe / 2)
    if amplitude == Amplitude.point:
        return np.asarray(z) / r**3
    return 1.0 / r**2


@dataclass(frozen=True)
class VoxelLattice:
    """Voxel planes parallel to the wall: depths (Z,), and a regular x-y grid in canonical
    order (x along axis 1, y along axis 0, both increasing)."""

    depths: np.ndarray
    origin: tuple[float, float]
    """(y0, x0) of the first voxel (m)."""
    step: tuple[float, float]
    """(dy, dx) voxel spacing (m)."""
    shape: tuple[int, int]
    """(ny, nx) voxels per plane."""

    @property
    def size(self) -> int:
        return int(self.depths.size * self.shape[0] * self.shape[1])

    @property
    def volume_shape(self) -> tuple[int, int, int]:
        return (int(self.depths.size),) + self.shape

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(y of rows, x of columns)."""
        ys = self.origin[0] + self.step[0] * np.arange(self.shape[0])
        xs = self.origin[1] + self.step[1] * np.arange(self.shape[1])
        return ys, xs

    def points(self) -> np.ndarray:
        """Voxel centres (Z, Y, X, 3)."""
        ys, xs = self.axes()
        y, x = np.meshgrid(ys, xs, indexing="ij")
        out = np.empty(self.volume_shape + (3,))
        out[..., 0] = x
        out[..., 1] = y
        out[..., 2] = self.depths[:, None, None]
        return out


@dataclass(frozen=True)
class OperatorOptions:
    """How a :class:`SceneOperator` evaluates: amplitude, precision, threads, cache."""

    amplitude: str = Amplitude.lambertian
    lobe: float = 0.0
    """Exponent k of a glossy lobe about the voxels' normal (lambertian only; 0: none)."""
    dtype: type = np.complex128
    workers: int = -1
    cache_mb: float = 1024.0
    """Memory for the kernels' spectra: cached for every plane and frequency when they fit,
    recomputed at every application otherwise."""


class SceneOperator:
    """A_f: albedo on a :class:`VoxelLattice` -> phasor fields on a regular wall grid.

    ``wall`` is the canonical layout of the wall grid (its spacing and the voxel
    spacing must be whole multiples of one another per axis); fields are (F, ny, nx)
    in that canonical order, albedos (Z, Y, X). With ``mask`` (ny, nx) the operator maps
    to the wall points where it is True only (M A, zero elsewhere; its adjoint A^H M):
    the kept points of a random scan.
    """

    def __init__(self, lattice: VoxelLattice, wall: GridLayout, geometry: CaptureGeometry,
                 frequencies: np.ndarray, options: OperatorOptions = OperatorOptions(),
                 mask: np.ndarray | None = None) -> None:
        self.lattice, self.wall, self.geometry = lattice, wall, geometry
        if mask is not None and np.shape(mask) != wall.shape:
            raise DataError(f"rsd_prior: a wall mask of shape {np.shape(mask)} for a "
                            f"{wall.shape} wall grid")
        self.mask = None if mask is None or np.all(mask) else np.asarray(mask, dtype=bool)
        self.frequencies = np.asarray(frequencies, dtype=float)
        self.options = options
        self.multiplier = path_multiplier(geometry)
        axes = [lattice_axis(lattice.shape[i], lattice.step[i], wall.shape[i], wall.spacing[i],
                             wall.origin[i] - lattice.origin[i]) for i in (0, 1)]
        if axes[0] is None or axes[1] is None:
            raise DataError(f"rsd_prior: the wall spacing {wall.spacing} m and the voxel "
                            f"spacing {lattice.step} m must be whole multiples of one another")
        self.threads = worker_count(options.workers)
        """Voxel planes propagated at once (each plane's own FFTs on one thread then)."""
        self.conv = PlaneConvolution(axes[0], axes[1], options.workers)
        self._plane_workers = 1 if self.threads > 1 else options.workers
        n_f, shape = self.frequencies.size, self.conv.shape
        itemsize = np.dtype(options.dtype).itemsize
        spectra_bytes = lattice.depths.size * n_f * shape[0] * shape[1] * itemsize
        self._cache = spectra_bytes <= options.cache_mb * 2**20
        self._spectra: dict[int, np.ndarray] = {}
        self._laser: dict[int, np.ndarray | None] = {}
        self._norms: np.ndarray | None = None
        self._weighted_norms: tuple[np.ndarray, np.ndarray] | None = None

    # ------------------------------------------------------------------ pieces
    @property
    def confocal(self) -> bool:
        return self.geometry.kind is CaptureKind.CONFOCAL

    @property
    def field_shape(self) -> tuple[int, int, int]:
        return (int(self.frequencies.size),) + self.wall.shape

    def kernel_spectra(self, index: int) -> np.ndarray:
        """FFT of the sensor-leg kernels g^k exp(-2 pi i f m r) of plane ``index``, (F, *shape)."""
        cached = self._spectra.get(index)
        if cached is not None:
            return cached
        z = float(self.lattice.depths[index])
        r = self.conv.distances(z)
        legs = 2 if self.confocal else 1
        amp = self._leg(r, z) ** legs
        kernels = phasor_series(self.frequencies, -self.multiplier * r, self.options.dtype,
                                scale=amp)
        spectra = self.conv.kernel_spectrum(kernels, self.options.dtype)
        if self._cache:
            self._spectra[index] = spectra
        return spectra

    def _leg(self, r: np.ndarray, z: float | np.ndarray) -> np.ndarray:
        return leg_amplitude(r, z, self.options.amplitude, self.options.lobe)

    def laser_leg(self, index: int) -> np.ndarray | None:
        """L_f(x_v) = g(r_l) exp(-2 pi i f r_l) on plane ``index``, (F, Y, X); None if confocal."""
        if self.confocal:
            return None
        if index in self._laser:
            return self._laser[index]
        z = float(self.lattice.depths[index])
        ys, xs = self.lattice.axes()
        lp = np.asarray(self.geometry.laser_point, dtype=float)
        r_l = np.sqrt((ys[:, None] - lp[1]) ** 2 + (xs[None, :] - lp[0]) ** 2 + (z - lp[2]) ** 2)
        leg = phasor_series(self.frequencies, -r_l, self.options.dtype,
                            scale=self._leg(r_l, z))
        if self._cache:
            self._laser[index] = leg
        return leg

    # ------------------------------------------------------------------ operator
    def forward(self, albedo: np.ndarray) -> np.ndarray:
        """A a: fields (F, ny, nx) of an albedo (Z, Y, X) (real or complex)."""
        albedo = np.asarray(albedo)
        self._check_albedo(albedo)
        planes = [i for i in range(albedo.shape[0]) if np.any(albedo[i])]
        threads = max(1, min(self.threads, len(planes)))
        sums: list[np.ndarray] = [self.conv.padded(self.frequencies.size, self.options.dtype)
                                  for _ in range(threads)]

        def accumulate(k: int) -> None:                  # every threads-th plane from k
            for i in planes[k::threads]:
                leg = self.laser_leg(i)
                source = (albedo[i][None] if leg is None else albedo[i][None] * leg).astype(
                    self.options.dtype, copy=False)
                sums[k] += self.kernel_spectra(i) * self.conv.input_spectrum(source,
                                                                       self._plane_workers)

        run_tasks(accumulate, range(threads), threads)
        acc = sums[0]
        for other in sums[1:]:
            acc += other
        out = self.conv.read_outputs(acc)
        if self.mask is not None:
            out *= self.mask
        return out

    def adjoint(self, fields: np.ndarray) -> np.ndarray:
        """A^H P: the complex back-propagation (Z, Y, X) of fields (F, ny, nx)."""
        fields = np.asarray(fields).astype(self.options.dtype, copy=False)
        if fields.shape != self.field_shape:
            raise DataError(f"rsd_prior: fields of shape {fields.shape}, expected "
                            f"{self.field_shape}")
        if self.mask is not None:
            fields = fields * self.mask
        spectrum = self.conv.output_spectrum(fields)
        out: np.ndarray = np.empty(self.lattice.volume_shape, dtype=self.options.dtype)

        def back_propagate(i: int) -> None:
            product = np.conj(self.kernel_spectra(i)) * spectrum
            leg = self.laser_leg(i)
            if leg is None:                  # confocal: no per-voxel factor, sum f first
                out[i] = self.conv.read_inputs(product.sum(axis=0, keepdims=True),
                                               self._plane_workers)[0]
            else:
                out[i] = np.einsum("fyx,fyx->yx", self.conv.read_inputs(
                    product, self._plane_workers), np.conj(leg))

        run_tasks(back_propagate, range(out.shape[0]), min(self.threads, out.shape[0]))
        return out

    def normal(self, albedo: np.ndarray) -> np.ndarray:
        """Re(A^H A a) for a real albedo: the Hessian of the least-squares data term."""
        return self.adjoint(self.forward(albedo)).real

    def column_norms(self, weights: np.ndarray | None = None) -> np.ndarray:
        """||A e_v|| for every voxel (Z, Y, X): sqrt(sum_f sum_s |A_f[s, v]|^2) (computed once
        per operator; read-only); with ``weights`` (the wall's (ny, nx), >= 0) the weighted
        norms sqrt(sum_f sum_s weights[s] |A_f[s, v]|^2), kept for the last weights asked
        (a fit solves one operator many times with the same ones)."""
        if self._norms is not None and weights is None:
            return self._norms
        w = None if weights is None else np.array(weights, dtype=float)
        if w is not None and self._weighted_norms is not None \
                and np.array_equal(self._weighted_norms[0], w):
            return self._weighted_norms[1]
        ones = (np.ones((1,) + self.wall.shape) if self.mask is None
                else self.mask[None].astype(float))
        if w is not None:
            ones = ones * w[None]
        out = np.empty(self.lattice.volume_shape)
        legs = 2 if self.confocal else 1
        lp = None if self.confocal else np.asarray(self.geometry.laser_point, dtype=float)
        ys, xs = self.lattice.axes()
        spectrum = self.conv.output_spectrum(ones)
        for i, z in enumerate(self.lattice.depths):
            r = self.conv.distances(float(z))
            power = self._leg(r, z) ** (2 * legs)
            kernel_spectrum = self.conv.kernel_spectrum(power[None], np.complex128)
            sums = self.conv.read_inputs(np.conj(kernel_spectrum) * spectrum)[0].real
            if lp is not None:
                r_l = np.sqrt((ys[:, None] - lp[1]) ** 2 + (xs[None, :] - lp[0]) ** 2
                              + (z - lp[2]) ** 2)
                sums = sums * self._leg(r_l, z) ** 2
            out[i] = np.sqrt(np.maximum(sums, 0.0) * self.frequencies.size)
        out.setflags(write=False)
        if w is None:
            self._norms = out
        else:
            self._weighted_norms = (w, out)
        return out

    def _check_albedo(self, albedo: np.ndarray) -> None:
        if albedo.shape != self.lattice.volume_shape:
            raise DataError(f"rsd_prior: albedo of shape {albedo.shape}, expected "
                            f"{self.lattice.volume_shape}")


def direct_fields(lattice: VoxelLattice, albedo: np.ndarray, points: np.ndarray,
                  geometry: CaptureGeometry, frequencies: np.ndarray,
                  options: OperatorOptions = OperatorOptions()) -> np.ndarray:
    """The same model summed directly over the voxels with non-zero albedo, at any wall
    points (N, 2 or 3): fields (F, N). For walls that are not grids compatible with the
    lattice."""
    pts = np.zeros((points.shape[0], 3))
    pts[:, :points.shape[1]] = points[:, :3]
    vox = lattice.points().reshape(-1, 3)
    a = np.asarray(albedo).reshape(-1)
    keep = np.flatnonzero(a)
    vox, a = vox[keep], a[keep]
    f = np.asarray(frequencies, dtype=float)
    out = np.zeros((f.size, pts.shape[0]), dtype=np.complex128)
    if a.size == 0:
        return out
    confocal = geometry.kind is CaptureKind.CONFOCAL
    m = path_multiplier(geometry)
    block = max(1, int(2**22 // max(pts.shape[0], 1)))
    for start in range(0, a.size, block):
        v, w = vox[start:start + block], a[start:start + block]
        r_s = np.sqrt(((v[:, None, :] - pts[None, :, :]) ** 2).sum(-1))      # (n, N)
        g_s = leg_amplitude(r_s, v[:, 2:3], options.amplitude, options.lobe)
        if confocal:
            path, scale = m * r_s, w[:, None] * g_s**2
        else:
            r_l = np.linalg.norm(v - np.asarray(geometry.laser_point, dtype=float), axis=-1)
            g_l = leg_amplitude(r_l, v[:, 2], options.amplitude, options.lobe)
            path, scale = r_l[:, None] + r_s, (w * g_l)[:, None] * g_s
        for i, phasor in phasor_steps(f, -path, scale=scale):
            out[i] += phasor.sum(axis=0)
    return out

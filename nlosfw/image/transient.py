"""What the classical (time-domain) imagers share: the field's transient, grids, voxels.

LCT, f-k migration and filtered backprojection are published as operators on the
confocal transient H(x_s, t). Like every nlosfw imager they take a
:class:`~nlosfw.transform.PhasorField`, and they get the transient back from it:

    h(x_s, t) = sum_f P'_f(x_s) exp(+2 pi i f t)

with P' the field with the device legs undone and t in metres of path from the
wall. h is the analytic (complex) signal of the transient filtered to the
field's band: a scatterer at path d gives the pulse sum_f exp(2 pi i f (t - d))
centred at t = d. For the full band of a capture (every DFT bin:
``transform.frequencies`` set to :func:`full_band_frequencies`) its real part is
the histogram itself (less its mean) and the imagers are the published
algorithms applied to its analytic signal; for a band-limited field (the default
transform, a field model's prediction) they image the transient of that band.
The field's spectral weights (a virtual illumination pulse, Liu 2019) are NOT
applied: the published methods undo the 1/r^n falloff by multiplying the
transient by a power of t, and over a pulse as long as the weighted ones (the
conformance kit's is sigma = 0.2 m of path) that gain moves the pulse's envelope
by (n - 1) sigma^2 / t, several centimetres of depth; the flat band's pulse is
about four times shorter. The operators are linear, so the image is
|volume|^2, the intensity every nlosfw imager returns.

Uniformly spaced frequencies make h periodic in t with period 1/df; the imagers
keep one period, starting a quarter period before the path to the nearest voxel. An
imager whose filter amplifies steps (``fbp``'s depth Laplacian) tapers the period's last
tenth to zero (a raised cosine, ``tapers_end``): cut off sharply where the t^(n-1) gain is
largest, the end of a measured capture's record rang into the farthest corner voxels
(fbp's image of the diffuse S was brightest at a corner 26 cm behind the S). ``lct`` and
``fk`` keep the whole period, as the authors' code does.

Geometry: confocal fields only (the published LCT and f-k are confocal; a
single-spot field is a one-line error). Voxels are planes parallel to the wall
whose (x, y) are samples of the field's regular wall grid (any subset, any
order); the imagers compute a volume on their own depth grid over the whole wall
and interpolate it linearly in depth at the voxels' depths.
"""

from __future__ import annotations

import dataclasses
import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar, TypeVar

import numpy as np

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.hints import ImagingHints
from nlosfw.common.config import Choice, require, require_threads
from nlosfw.common.errors import DataError
from nlosfw.common.memory import PlanShape
from nlosfw.common.progress import ProgressCallback, ProgressCounter
from nlosfw.image.arrays import Device, DeviceImager
from nlosfw.image.data_settings import FALLOFFS, binned_wall, estimated_snr, sparsity
from nlosfw.image.interface import Imager, ImagerConfig
from nlosfw.image.plane_convolution import plane_layout, to_canonical, wall_layout
from nlosfw.image.propagation import check_field, check_voxels
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.rsd_kernel import wall_field
from nlosfw.transform.field import PhasorField
from nlosfw.transform.frequencies import uniform_step


class Falloff(Choice):
    """How the returning light falls off with the distance r to the wall, undone before
    imaging: ``diffuse`` 1/r^4 (O'Toole's default), ``retroreflective`` 1/r^2."""

    diffuse = "diffuse"
    retroreflective = "retroreflective"


@dataclass(frozen=True)
class TransientImagerConfig(ImagerConfig):
    """Options shared by the ``lct``, ``fk`` and ``fbp`` imagers."""

    falloff: Falloff | None = None
    """Radiometric falloff undone before imaging (diffuse 1/r^4, retroreflective 1/r^2);
    null: the capture's imaging hint when it states one, else the one giving the sharper
    volume (estimated from the data: nlosfw.image.data_settings)."""
    samples_per_wavelength: float = 4.0
    """Time samples per shortest wavelength of the field's band (dt = 1/(this x f_max))."""
    workers: int = -1
    """Threads of scipy.fft (-1: all cores)."""
    device: Device = Device.cpu
    """``cpu``: numpy; ``cuda``: the FFTs and products on a CUDA device through an array
    backend plugin (nlosfw-torch); ``auto``: cuda when one is seen, else cpu
    (:mod:`nlosfw.image.arrays`)."""

    def __post_init__(self) -> None:
        require(self.samples_per_wavelength >= 2, "samples_per_wavelength",
                f"must be >= 2 (Nyquist), got {self.samples_per_wavelength}")
        require_threads(self.workers, "workers", -1, "all cores")



@dataclass(frozen=True, eq=False)
class WallGrid:
    """The field's wall as a canonical regular grid: values (F, Y, X) with the device legs
    undone, origin (y0, x0) and spacing (dy, dx) in metres."""

    values: np.ndarray
    origin: tuple[float, float]
    spacing: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.values.shape[1]), int(self.values.shape[2])

    @property
    def lateral_reach(self) -> float:
        """Largest lateral distance between two wall samples (m)."""
        ny, nx = self.shape
        return float(np.hypot((ny - 1) * self.spacing[0], (nx - 1) * self.spacing[1]))


@dataclass(frozen=True, eq=False)
class VoxelPlanes:
    """Where each voxel lies in the canonical wall grid: per plane its depth, per voxel its
    (row, column) index; ``shape`` is the voxels' shape without the last axis."""

    depths: np.ndarray          # (Z,)
    rows: np.ndarray            # (Z, Y, X) int
    cols: np.ndarray            # (Z, Y, X) int
    shape: tuple[int, ...]


TransientConfigT = TypeVar("TransientConfigT", bound=TransientImagerConfig)


class TransientImager(DeviceImager, Imager[TransientConfigT]):
    """Base of the imagers that work on the field's transient (see the module docstring)."""

    config_class: ClassVar[type] = TransientImagerConfig
    imager_name: ClassVar[str] = "transient"
    full_grid_only: ClassVar[bool] = True
    tapers_end: ClassVar[bool] = False
    """Whether :meth:`transient` tapers the window's end (:func:`end_taper`)."""
    estimates_snr: ClassVar[bool] = False
    """Whether the imager takes a Wiener SNR (its ``snr`` option, the hint, the estimate)."""

    def reconstruct(self, field: PhasorField, voxels: np.ndarray,
                    on_progress: ProgressCallback | None = None) -> Reconstruction:
        """Intensity |volume|^2 at ``voxels`` (a plane or planes on the wall's grid);
        ``on_progress(done, total)`` after the whole-volume transform and after the voxel
        lookup (these imagers have no smaller unit of work)."""
        progress = ProgressCounter(2, on_progress)
        field = check_field(field)
        if field.geometry.kind is not CaptureKind.CONFOCAL:
            raise DataError(f"field.geometry: the {self.imager_name} imager images confocal "
                            f"fields only (got {field.geometry.kind.value}); use the rsd or fft "
                            "imager for single-spot captures")
        voxels = check_voxels(voxels)
        grid = canonical_wall(field)
        planes = voxel_planes(voxels, grid, self.imager_name)
        f_max = float(field.frequencies.max())
        dt = 1.0 / (self.config.samples_per_wavelength * f_max)
        window = time_window(field.frequencies, float(planes.depths.min()))
        field = self._settled(field, grid, planes.depths, dt, window)
        volume, info = self._planes(field, grid, planes.depths, dt, window)   # (Z, Y, X)
        progress.advance()
        image = volume.real ** 2 + volume.imag ** 2
        intensity = image[np.arange(planes.depths.size)[:, None, None], planes.rows, planes.cols]
        progress.advance()
        meta: dict[str, object] = {
            "imager": self.imager_name,
            "frequencies": [float(f) for f in field.frequencies],
            "weights_applied": False,
            "capture_kind": field.geometry.kind.value,
            "falloff": str(self.falloff_for(field)),
            "settings": field_hints(field).origin,
            "time_step": dt,
            "time_window": list(window),
            "n_voxels": int(np.prod(planes.shape)),
            **info,   # no wall-clock time: same field, same bytes (timings: metrics.json)
        }
        return Reconstruction(intensity=np.asarray(intensity.reshape(planes.shape), float),
                              voxels=voxels, metadata=meta)

    @abstractmethod
    def _planes(self, field: PhasorField, grid: WallGrid, depths: np.ndarray, dt: float,
                window: tuple[float, float]) -> tuple[np.ndarray, dict[str, object]]:
        """(complex volume (len(depths), Y, X) over the whole wall grid, metadata)."""

    def settled_hints(self, field: PhasorField, voxels: np.ndarray) -> ImagingHints:
        """The settings this imager images ``field`` with at ``voxels``: each option set,
        else the field's hint, else estimated from the field (:mod:`~nlosfw.image.
        data_settings`); ``origin`` says where each comes from. A run estimates them once,
        from the capture's own field, and images every source with them."""
        field = check_field(field)
        grid = canonical_wall(field)
        planes = voxel_planes(check_voxels(voxels), grid, self.imager_name)
        dt = 1.0 / (self.config.samples_per_wavelength * float(field.frequencies.max()))
        window = time_window(field.frequencies, float(planes.depths.min()))
        return field_hints(self._settled(field, grid, planes.depths, dt, window))

    def _settled(self, field: PhasorField, grid: WallGrid, depths: np.ndarray, dt: float,
                 window: tuple[float, float]) -> PhasorField:
        """``field`` carrying, as its hints, the falloff (and SNR) this imager uses: the
        option, else the field's hint, else the estimate from the data."""
        hints = field_hints(field)
        said = [hints.origin] if hints.origin else []
        snr_option = getattr(self.config, "snr", None)
        if self.estimates_snr and snr_option is None and hints.snr is None:
            estimate = estimated_snr(grid.values, field.frequencies, grid.spacing)
            hints = dataclasses.replace(hints, snr=estimate.value)
            said.append(estimate.why)
        elif snr_option is not None:
            said.append(f"snr {snr_option:g}: the snr option")
        if self.config.falloff is None and hints.falloff is None:
            choice, why = self._sharpest_falloff(field.replace(imaging_hints=hints), grid,
                                                 depths, dt, window)
            hints = dataclasses.replace(hints, falloff=choice)
            said.append(why)
        elif self.config.falloff is not None:
            said.append(f"falloff {Falloff(self.config.falloff)}: the falloff option")
        # settled hints settled again (a run's sources): each line said once
        said = [line for i, line in enumerate(said)
                if not any(line in earlier for earlier in said[:i])]
        return field.replace(imaging_hints=dataclasses.replace(hints, origin="; ".join(said)))

    def _sharpest_falloff(self, field: PhasorField, grid: WallGrid, depths: np.ndarray,
                          dt: float, window: tuple[float, float]) -> tuple[str, str]:
        """(the falloff whose volume is the sharpest, the line that says so): each
        candidate imaged on the binned wall (:func:`~nlosfw.image.data_settings.binned_wall`)."""
        values, origin, spacing = binned_wall(grid.values, grid.origin, grid.spacing)
        small = WallGrid(values=values, origin=origin, spacing=spacing)
        hints = field_hints(field)
        scores = {}
        for candidate in FALLOFFS:
            trial = field.replace(imaging_hints=dataclasses.replace(hints, falloff=candidate))
            volume, _ = self._planes(trial, small, depths, dt, window)
            scores[candidate] = sparsity(volume.real ** 2 + volume.imag ** 2)
        best = max(FALLOFFS, key=lambda c: scores[c])     # the first of equals
        return best, (f"falloff {best} estimated from the data: the sharper volume (sparsity "
                      + ", ".join(f"{scores[c]:.3g} {c}" for c in FALLOFFS) + ")")

    def falloff_for(self, field: PhasorField) -> Falloff:
        """The falloff undone for ``field``: the ``falloff`` option if set, else the field's
        imaging hint (:mod:`nlosfw.capture.hints`; :meth:`reconstruct` puts the estimate
        from the data there when the capture states none), else diffuse."""
        if self.config.falloff is not None:
            return Falloff(self.config.falloff)
        hint = field_hints(field).falloff
        return Falloff(hint) if hint is not None else Falloff.diffuse

    def transient(self, field: PhasorField, grid: WallGrid, times: np.ndarray,
                  window: tuple[float, float]) -> np.ndarray:
        """h at ``times`` (path from the wall, m) inside ``window``, zero outside: (T, Y, X),
        complex64, times the falloff compensation d^(n-1), d = t/2 the distance (and the
        end taper where the imager ``tapers_end``)."""
        t = np.asarray(times, dtype=float)
        inside = (t >= window[0]) & (t < window[1])
        out = np.zeros((t.size,) + grid.shape, dtype=np.complex64)
        if not inside.any():
            return out
        coeffs = self.transient_coefficients(field, t[inside], window)   # (T', F)
        flat = grid.values.reshape(grid.values.shape[0], -1)
        out[inside] = (coeffs @ flat).reshape((-1,) + grid.shape)
        return out

    def transient_coefficients(self, field: PhasorField, times: np.ndarray,
                               window: tuple[float, float]) -> np.ndarray:
        """(T, F) complex128: h at ``times`` (all inside ``window``) is these rows times
        the wall grid's values (F, Y·X): exp(2 pi i f t) times the falloff compensation
        and the end taper (:meth:`transient`)."""
        coeffs = np.exp(2j * np.pi * np.outer(times, field.frequencies))
        power = 4 if self.falloff_for(field) == "diffuse" else 2          # 1/r^n falloff
        gain = (times / 2.0) ** (power - 1)
        if self.tapers_end:
            gain = gain * end_taper(times, window)
        coeffs *= gain[:, None]
        return coeffs

    def window_coefficients(self, field: PhasorField, times: np.ndarray,
                            window: tuple[float, float]) -> np.ndarray:
        """:meth:`transient_coefficients` at every one of ``times``, zero rows outside
        ``window`` (T, F): the device code's transient is these rows times the wall."""
        t = np.asarray(times, dtype=float)
        inside = (t >= window[0]) & (t < window[1])
        coeffs = np.zeros((t.size, field.frequencies.size), dtype=np.complex128)
        if inside.any():
            coeffs[inside] = self.transient_coefficients(field, t[inside], window)
        return coeffs


def end_taper(times: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """1 over ``window`` but its last :data:`END_TAPER` share, which falls to 0 as a raised
    cosine (all ones for an unbounded window)."""
    start, end = window
    if not np.isfinite(end):
        return np.ones_like(times)
    edge = END_TAPER * (end - start)
    rest = np.clip((end - times) / edge, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * rest)


#: Share of the transient's window, at its end, tapered to zero (:func:`end_taper`).
END_TAPER = 0.1


def field_hints(field: PhasorField) -> ImagingHints:
    """The imaging hints the field carries from its capture (empty when none)."""
    return field.imaging_hints or ImagingHints()


def canonical_wall(field: PhasorField) -> WallGrid:
    """The field's wall as a :class:`WallGrid` (DataError unless it is a regular grid)."""
    wall = wall_layout(field)
    values = np.ascontiguousarray(to_canonical(wall_field(field), wall.order, axes=(1, 2)))
    return WallGrid(values=values, origin=wall.origin, spacing=wall.spacing)


def voxel_planes(voxels: np.ndarray, grid: WallGrid, name: str) -> VoxelPlanes:
    """Each voxel's plane depth and wall-grid index; DataError unless every plane is parallel
    to the wall and every voxel's (x, y) is a wall sample."""
    planes = voxels.reshape((-1,) + voxels.shape[-3:]) if voxels.ndim >= 3 else None
    if planes is None:
        raise DataError(f"voxels: the {name} imager needs planes parallel to the wall, (Y, X, 3) "
                        f"or (Z, Y, X, 3); got a point list {voxels.shape} (use the rsd imager)")
    depths = np.array([plane_layout(p, i)[1] for i, p in enumerate(planes)])
    (y0, x0), (dy, dx) = grid.origin, grid.spacing
    ny, nx = grid.shape
    rows_f = (planes[..., 1] - y0) / dy if ny > 1 else np.zeros(planes.shape[:-1])
    cols_f = (planes[..., 0] - x0) / dx if nx > 1 else np.zeros(planes.shape[:-1])
    rows, cols = np.rint(rows_f).astype(np.int64), np.rint(cols_f).astype(np.int64)
    off = (np.abs(rows_f - rows) > 1e-3) | (np.abs(cols_f - cols) > 1e-3)
    off |= (rows < 0) | (rows >= ny) | (cols < 0) | (cols >= nx)
    if off.any():
        bad = planes[np.unravel_index(int(np.argmax(off)), off.shape)]
        raise DataError(f"voxels: the {name} imager images the wall's own grid (x, y), and "
                        f"voxel ({bad[0]:.6g}, {bad[1]:.6g}) is not one of its samples; use "
                        "the rsd or fft imager for other voxels")
    return VoxelPlanes(depths=depths, rows=rows, cols=cols, shape=voxels.shape[:-1])


def time_window(frequencies: np.ndarray, nearest_depth: float) -> tuple[float, float]:
    """[start, end) of the transient kept: one period 1/df of a uniformly spaced band,
    starting a quarter period before the nearest voxel's path 2 z (or from 0); everything
    from 0 for other frequency sets."""
    f = np.sort(np.asarray(frequencies, dtype=float))
    step = uniform_step(f) if f.size > 1 else None
    if step is None:
        return 0.0, float("inf")
    period = 1.0 / step
    start = max(0.0, 2.0 * nearest_depth - period / 4)
    return start, start + period


def full_band_frequencies(n_bins: int, delta_t: float) -> np.ndarray:
    """Every positive DFT bin k / (n_bins delta_t), k = 1 .. n_bins/2, of a capture: with
    ``transform.frequencies`` set to these the classical imagers see the whole transient."""
    return np.arange(1, n_bins // 2 + 1) / (n_bins * delta_t)


#: [1/m] The band for imaging measured captures with the transient imagers: 0.4-60 cycles/m
#: images clean on the Stanford LCT captures (the wall-aliasing band 5.7-22.9 gives
#: poor classical images; the full 4 ps band is noisy and needs 6-9 GB).
MEASURED_BAND = (0.4, 60.0)


def measured_band_frequencies(n_bins: int, delta_t: float,
                              band: tuple[float, float] = MEASURED_BAND) -> np.ndarray:
    """The capture's DFT bins (:func:`full_band_frequencies`) within ``band`` (cycles per
    metre of path): the imaging band for measured captures (at least two bins)."""
    every = full_band_frequencies(n_bins, delta_t)
    kept = every[(every >= band[0]) & (every <= band[1])]
    return kept if kept.size >= 2 else every[:2]


def lateral_frequencies(n: int, spacing: float) -> np.ndarray:
    """FFT frequencies (cycles/m) of a padded axis of ``n`` samples ``spacing`` apart."""
    return np.fft.fftfreq(n, d=spacing) if n > 1 else np.zeros(1)


def interpolate_depths(volume: np.ndarray, z0: float, dz: float,
                       depths: np.ndarray) -> np.ndarray:
    """Linear interpolation along axis 0 of a volume sampled at z0 + k dz, at ``depths``
    (zero outside)."""
    pos = (np.asarray(depths, dtype=float) - z0) / dz
    i0 = np.floor(pos).astype(np.int64)
    frac = (pos - i0).astype(np.float32)[:, None, None]
    n = volume.shape[0]
    lo = np.where((i0 >= 0) & (i0 < n), i0, 0)
    hi = np.where((i0 + 1 >= 0) & (i0 + 1 < n), i0 + 1, 0)
    a = np.where(((i0 >= 0) & (i0 < n))[:, None, None], volume[lo], 0)
    b = np.where(((i0 + 1 >= 0) & (i0 + 1 < n))[:, None, None], volume[hi], 0)
    return a * (1 - frac) + b * frac


def wall_shape(shape: PlanShape) -> tuple[int, int]:
    """The wall grid (ny, nx) of a run of ``shape`` (a square of its sensors when the grid
    is not known yet)."""
    if shape.grid is not None:
        return int(shape.grid[0]), int(shape.grid[1])
    side = max(1, math.isqrt(max(1, int(shape.sensors))))
    return side, side


def transient_sizes(config: TransientImagerConfig, shape: PlanShape
                    ) -> tuple[float, tuple[float, float] | None, float | None]:
    """(lateral reach of the wall (m), the depths imaged (nearest, farthest; m), the time
    step dt (m)) of a run of ``shape``, as the imagers derive them; None where the shape
    does not know them yet (the band's top, the depth range)."""
    ny, nx = wall_shape(shape)
    spacing = float(shape.spacing or 0.0)
    reach = math.hypot((ny - 1) * spacing, (nx - 1) * spacing)
    dt = (None if not shape.f_max else 1.0 / (config.samples_per_wavelength * shape.f_max))
    depths = None if shape.depth_range is None else (float(shape.depth_range[0]),
                                                     float(shape.depth_range[1]))
    return reach, depths, dt

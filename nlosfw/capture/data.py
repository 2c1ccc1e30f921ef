"""The transient capture, mirrored field for field from y-tal's ``NLOSCaptureData``.

Conventions (as in y-tal): the relay wall is the plane z = 0 and the hidden scene
lies at z > 0; times are optical path lengths in metres; axis 0 of ``H`` is time.
Bin ``i`` holds the paths of length in ``[t_start + i*delta_t, t_start + (i+1)*delta_t)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat, VolumeFormat
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.capture.hints import ImagingHints, hints_from
from nlosfw.capture.scene_info import check_scene_info
from nlosfw.common.errors import DataError

#: The fields of a capture in y-tal's order; each is one top-level HDF5 dataset.
YTAL_FIELDS = (
    "H",
    "H_format",
    "sensor_xyz",
    "sensor_grid_xyz",
    "sensor_grid_normals",
    "sensor_grid_format",
    "laser_xyz",
    "laser_grid_xyz",
    "laser_grid_normals",
    "laser_grid_format",
    "volume_format",
    "delta_t",
    "t_start",
    "t_accounts_first_and_last_bounces",
    "scene_info",
)

_H_NDIM = {
    HFormat.T_Sx_Sy: 3,
    HFormat.T_Lx_Ly_Sx_Sy: 5,
    HFormat.T_Si: 2,
    HFormat.T_Li_Si: 3,
    HFormat.F_Sx_Sy: 3,
    HFormat.F_Lx_Ly_Sx_Sy: 5,
    HFormat.F_Si: 2,
    HFormat.F_Li_Si: 3,
}
_TIME_FORMATS = (HFormat.T_Sx_Sy, HFormat.T_Lx_Ly_Sx_Sy, HFormat.T_Si, HFormat.T_Li_Si)


#: The bin widths (metres of optical path) a capture may have: 0.1 micrometre (0.33 fs)
#: to 1 km (3.3 microseconds); anything outside is a unit mistake or a hostile file.
MIN_DELTA_T, MAX_DELTA_T = 1e-7, 1e3

@dataclass(frozen=True, eq=False)
class Capture:
    """A transient measurement H with its full acquisition geometry.

    Field names, shapes and meaning are those of y-tal's HDF5 format, so a
    :class:`Capture` written by :func:`nlosfw.capture.write_capture` opens in y-tal
    unchanged. Arrays are not copied; do not modify them after construction.
    """

    H: np.ndarray
    """The transient; axis 0 is time. Shape set by ``H_format``."""
    H_format: HFormat
    sensor_grid_xyz: np.ndarray
    """Sensor points on the wall: (X, Y, 3) for ``X_Y_3`` grids or (N, 3)."""
    laser_grid_xyz: np.ndarray
    """Laser points on the wall: one point (single spot), the sensor grid (confocal), or a grid."""
    delta_t: float
    """Bin width in metres of optical path."""
    t_start: float = 0.0
    """Optical path length at the start of bin 0, in metres."""
    t_accounts_first_and_last_bounces: bool = False
    sensor_grid_normals: np.ndarray | None = None
    laser_grid_normals: np.ndarray | None = None
    sensor_grid_format: GridFormat = GridFormat.X_Y_3
    laser_grid_format: GridFormat = GridFormat.X_Y_3
    sensor_xyz: np.ndarray | None = None
    """Position of the sensor device (3,), if known."""
    laser_xyz: np.ndarray | None = None
    """Position of the laser device (3,), if known."""
    volume_format: VolumeFormat = VolumeFormat.UNKNOWN
    scene_info: dict[str, Any] = field(default_factory=dict)
    """Free metadata: generating config, ground truth, noise, provenance."""
    imaging_hints: ImagingHints | None = None
    """The imaging settings the capture states (:mod:`nlosfw.capture.hints`; None: none). Not
    one of y-tal's fields: a file keeps them in ``scene_info["imaging_hints"]``, which is
    read into this attribute (and out of ``scene_info``) when a capture is made."""

    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen: normalise types once, at construction
        try:
            set_(self, "H_format", HFormat(self.H_format))
            set_(self, "sensor_grid_format", GridFormat(self.sensor_grid_format))
            set_(self, "laser_grid_format", GridFormat(self.laser_grid_format))
            set_(self, "volume_format", VolumeFormat(self.volume_format))
        except ValueError as err:
            raise DataError(f"invalid enum value: {err}") from None
        set_(self, "H", np.asarray(self.H))
        for name in ("sensor_grid_xyz", "laser_grid_xyz", "sensor_grid_normals",
                     "laser_grid_normals", "sensor_xyz", "laser_xyz"):
            value = getattr(self, name)
            if value is not None:
                set_(self, name, np.asarray(value, dtype=np.float64))
        info, hints = hints_from(self.scene_info or {})
        set_(self, "scene_info", info)
        if self.imaging_hints is None and hints is not None:
            set_(self, "imaging_hints", hints)
        self._validate()

    # ----------------------------------------------------------------- checks
    def _validate(self) -> None:
        H = self.H
        if self.H_format is HFormat.UNKNOWN:
            raise DataError("H_format: UNKNOWN is not supported; valid: T_Sx_Sy, T_Si, "
                            "T_Lx_Ly_Sx_Sy, T_Li_Si")
        if not (np.issubdtype(H.dtype, np.floating) or np.issubdtype(H.dtype, np.complexfloating)):
            raise DataError(f"H: dtype {H.dtype} is not a float type; valid: float32 or float64")
        ndim = _H_NDIM[self.H_format]
        if H.ndim != ndim:
            raise DataError(f"H: has {H.ndim} axes but H_format {self.H_format.name} needs {ndim}")
        if H.size == 0:
            raise DataError(f"H: is empty (shape {H.shape})")
        bad = np.size(H) - int(np.count_nonzero(np.isfinite(H)))
        if bad:
            raise DataError(f"H: contains {bad} NaN or inf values out of {H.size}; "
                            "a capture must be finite")
        if not (np.isfinite(self.delta_t) and self.delta_t > 0):
            raise DataError(f"delta_t: must be a positive number of metres, got {self.delta_t}")
        if not MIN_DELTA_T <= self.delta_t <= MAX_DELTA_T:
            raise DataError(f"delta_t: must be a bin width between {MIN_DELTA_T:g} and "
                            f"{MAX_DELTA_T:g} metres of optical path, got {self.delta_t:g}")
        if self.t_start is None or not np.isfinite(self.t_start):
            raise DataError(f"t_start: must be a finite number of metres, got {self.t_start}")
        object.__setattr__(self, "delta_t", float(self.delta_t))
        object.__setattr__(self, "t_start", float(self.t_start))
        for name in ("sensor_xyz", "laser_xyz"):
            value = getattr(self, name)
            if value is not None and value.shape != (3,):
                raise DataError(f"{name}: must have shape (3,), got {value.shape}")
            if value is not None and not np.all(np.isfinite(value)):
                raise DataError(f"{name}: must be finite, got {value.tolist()}")
        sensor_shape = self._check_grid("sensor", self.sensor_grid_xyz, self.sensor_grid_format,
                                        self.sensor_grid_normals)
        laser_shape = self._check_grid("laser", self.laser_grid_xyz, self.laser_grid_format,
                                       self.laser_grid_normals)
        spatial = H.shape[1:]
        if self.H_format in (HFormat.T_Sx_Sy, HFormat.F_Sx_Sy, HFormat.T_Si, HFormat.F_Si):
            if sensor_shape != spatial:
                raise DataError(f"sensor_grid_xyz: grid shape {sensor_shape} does not match "
                                f"H's sensor axes {spatial}")
            n_laser = int(np.prod(laser_shape))
            if n_laser != 1 and laser_shape != sensor_shape:
                raise DataError(f"laser_grid_xyz: shape {laser_shape} is neither one point "
                                f"(single spot) nor the sensor grid {sensor_shape} (confocal)")
            if laser_shape == sensor_shape and n_laser != 1 and not np.allclose(
                self.laser_grid_xyz, self.sensor_grid_xyz, atol=1e-6
            ):
                raise DataError("laser_grid_xyz: paired laser and sensor points must coincide "
                                "(confocal); other pairings are not supported")
        else:
            n_l = len(laser_shape)
            if spatial[:n_l] != laser_shape or spatial[n_l:] != sensor_shape:
                raise DataError(f"H: shape {H.shape} does not match laser grid {laser_shape} "
                                f"and sensor grid {sensor_shape}")
        if self.t_accounts_first_and_last_bounces and (
            self.sensor_xyz is None or self.laser_xyz is None
        ):
            raise DataError("t_accounts_first_and_last_bounces: true needs sensor_xyz and "
                            "laser_xyz")
        check_scene_info(self.scene_info)

    @staticmethod
    def _check_grid(which: str, xyz: np.ndarray, fmt: GridFormat,
                    normals: np.ndarray | None) -> tuple[int, ...]:
        name = f"{which}_grid_xyz"
        if xyz is None:
            raise DataError(f"{name}: is missing")
        if xyz.shape[-1:] != (3,):
            raise DataError(f"{name}: last axis must have 3 coordinates, got shape {xyz.shape}")
        if fmt is GridFormat.X_Y_3 and xyz.ndim != 3:
            raise DataError(f"{name}: {which}_grid_format X_Y_3 needs shape (X, Y, 3), "
                            f"got {xyz.shape}")
        if fmt is GridFormat.N_3 and xyz.ndim != 2:
            raise DataError(f"{name}: {which}_grid_format N_3 needs shape (N, 3), got {xyz.shape}")
        if fmt is GridFormat.UNKNOWN:
            raise DataError(f"{which}_grid_format: UNKNOWN; valid: N_3, X_Y_3")
        if not np.all(np.isfinite(xyz)):
            raise DataError(f"{name}: contains NaN or inf")
        if normals is not None:
            if normals.shape != xyz.shape:
                raise DataError(f"{which}_grid_normals: shape {normals.shape} does not match "
                                f"{name} {xyz.shape}")
            if not np.all(np.isfinite(normals)):
                raise DataError(f"{which}_grid_normals: contains NaN or inf")
            zero = int(np.count_nonzero(np.linalg.norm(normals, axis=-1) < 1e-12))
            if zero:
                raise DataError(f"{which}_grid_normals: {zero} of them have zero length; "
                                "every normal needs a direction")
        return tuple(xyz.shape[:-1])

    # ------------------------------------------------------------- properties
    @property
    def kind(self) -> CaptureKind:
        """Single spot, confocal or exhaustive (from the formats and grids)."""
        if self.H_format in (HFormat.T_Lx_Ly_Sx_Sy, HFormat.T_Li_Si,
                             HFormat.F_Lx_Ly_Sx_Sy, HFormat.F_Li_Si):
            return CaptureKind.EXHAUSTIVE
        if self.laser_grid_xyz.shape == self.sensor_grid_xyz.shape and np.allclose(
            self.laser_grid_xyz, self.sensor_grid_xyz, atol=1e-6
        ):
            return CaptureKind.CONFOCAL
        return CaptureKind.SINGLE_SPOT  # validation admits only one laser point otherwise

    @property
    def is_confocal(self) -> bool:
        return self.kind is CaptureKind.CONFOCAL

    @property
    def is_time_domain(self) -> bool:
        return self.H_format in _TIME_FORMATS

    @property
    def n_bins(self) -> int:
        return int(self.H.shape[0])

    @property
    def bin_centers(self) -> np.ndarray:
        """Optical path length (m) at the centre of each time bin."""
        return self.t_start + (np.arange(self.n_bins) + 0.5) * self.delta_t

    @property
    def sensor_points(self) -> np.ndarray:
        """Sensor points as (N, 3), in the order of H's flattened sensor axes."""
        return self.sensor_grid_xyz.reshape(-1, 3)

    @property
    def grid_shape(self) -> tuple[int, ...]:
        """Shape of the sensor grid: (X, Y) or (N,)."""
        return tuple(self.sensor_grid_xyz.shape[:-1])

    @property
    def laser_point(self) -> np.ndarray:
        """The single laser spot on the wall (3,); an error for other kinds."""
        if self.kind is not CaptureKind.SINGLE_SPOT:
            raise DataError(f"laser_grid_xyz: a {self.kind.value} capture has no single laser spot")
        return self.laser_grid_xyz.reshape(3)

    @property
    def geometry(self) -> CaptureGeometry:
        """The acquisition geometry without the measurements."""
        kind = self.kind
        return CaptureGeometry(
            kind=kind,
            laser_point=self.laser_point if kind is CaptureKind.SINGLE_SPOT else None,
            laser_xyz=self.laser_xyz,
            sensor_xyz=self.sensor_xyz,
            t_accounts_first_and_last_bounces=self.t_accounts_first_and_last_bounces,
        )

    def replace(self, **changes: Any) -> Capture:
        """A new capture with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

"""Where light enters and leaves the relay wall: the acquisition geometry of a capture."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TypedDict

import numpy as np
from numpy.typing import ArrayLike

from nlosfw.capture.enums import CaptureKind
from nlosfw.common.errors import DataError

#: Speed of light in vacuum (m/s); times in nlosfw are optical path lengths c*t.
SPEED_OF_LIGHT = 299_792_458.0


def device_legs(laser_points: ArrayLike, sensor_points: ArrayLike,
                laser_xyz: ArrayLike, sensor_xyz: ArrayLike) -> np.ndarray:
    """Optical path of the device legs |laser_xyz - x_l| + |x_s - sensor_xyz|, shape (S,)."""
    sensors = np.asarray(sensor_points, dtype=float)
    laser = np.asarray(laser_points, dtype=float)
    leg_l = np.linalg.norm(laser - np.asarray(laser_xyz, dtype=float), axis=-1)
    leg_s = np.linalg.norm(sensors - np.asarray(sensor_xyz, dtype=float), axis=-1)
    return leg_l + leg_s


class GeometryDict(TypedDict):
    """A :class:`CaptureGeometry` as plain values (YAML, HDF5 attributes)."""

    kind: str
    laser_point: list[float] | None
    laser_xyz: list[float] | None
    sensor_xyz: list[float] | None
    t_accounts_first_and_last_bounces: bool


@dataclass(frozen=True, eq=False)
class CaptureGeometry:
    """Where light enters and leaves the relay wall, without the measurements.

    Phasor fields carry this so that an imager can undo the laser-side leg
    (single spot), double the path (confocal) and remove the device legs.
    """

    kind: CaptureKind
    laser_point: np.ndarray | None = None
    """The laser spot on the wall, shape (3,), for single-spot captures."""
    laser_xyz: np.ndarray | None = None
    """Position of the laser device, shape (3,), if known."""
    sensor_xyz: np.ndarray | None = None
    """Position of the sensor device, shape (3,), if known."""
    t_accounts_first_and_last_bounces: bool = False
    """Whether the device-to-wall legs are included in the time axis."""

    def __post_init__(self) -> None:
        for name in ("laser_point", "laser_xyz", "sensor_xyz"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise DataError(f"{name}: must be 3 finite numbers, got {arr.tolist()}")

    def device_path(self, wall_points: np.ndarray) -> np.ndarray:
        """Length of the device legs for light measured at ``wall_points`` (..., 3).

        Zero everywhere unless the time axis includes the device legs. For a
        single spot it is |laser_xyz - laser_point| + |wall_point - sensor_xyz|;
        for confocal scans the laser also moves: |laser_xyz - p| + |p - sensor_xyz|.
        """
        wall_points = np.asarray(wall_points, dtype=float)
        out = np.zeros(wall_points.shape[:-1])
        if not self.t_accounts_first_and_last_bounces:
            return out
        if self.sensor_xyz is None or self.laser_xyz is None:
            raise DataError(
                "t_accounts_first_and_last_bounces is true but sensor_xyz or laser_xyz "
                "is missing; both device positions are needed to remove the device legs"
            )
        if self.kind is CaptureKind.CONFOCAL:
            laser_points = wall_points
        elif self.laser_point is None:
            raise DataError("single-spot geometry needs its laser_point")
        else:
            laser_points = self.laser_point
        return out + device_legs(laser_points, wall_points, self.laser_xyz, self.sensor_xyz)

    def to_dict(self) -> GeometryDict:
        """Plain values for YAML or HDF5 attributes."""
        def plain(a: np.ndarray | None) -> list[float] | None:
            return None if a is None else [float(v) for v in np.asarray(a).reshape(3)]

        return {
            "kind": self.kind.value,
            "laser_point": plain(self.laser_point),
            "laser_xyz": plain(self.laser_xyz),
            "sensor_xyz": plain(self.sensor_xyz),
            "t_accounts_first_and_last_bounces": bool(self.t_accounts_first_and_last_bounces),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> CaptureGeometry:
        """Inverse of :meth:`to_dict` (of a :class:`GeometryDict` as read from a file: a
        one-line DataError for anything else)."""
        def arr(v: object) -> np.ndarray | None:
            if v is None:
                return None
            if not isinstance(v, (Sequence, np.ndarray)):
                raise TypeError(f"a point must be 3 numbers, got {v!r}")
            return np.asarray(v, dtype=float).reshape(3)

        try:
            return cls(
                kind=CaptureKind(data["kind"]),
                laser_point=arr(data.get("laser_point")),
                laser_xyz=arr(data.get("laser_xyz")),
                sensor_xyz=arr(data.get("sensor_xyz")),
                t_accounts_first_and_last_bounces=bool(
                    data.get("t_accounts_first_and_last_bounces", False)
                ),
            )
        except (KeyError, ValueError, TypeError) as err:
            raise DataError(f"capture geometry: invalid value ({err})") from None

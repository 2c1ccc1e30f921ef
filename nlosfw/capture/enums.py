"""Enumerations mirrored value for value from y-tal (``tal.enums``).

The integer values are part of the HDF5 file format: y-tal stores these fields
as HDF5 enum datasets and reads them back by value.
"""

from __future__ import annotations

from enum import Enum, IntEnum


class HFormat(IntEnum):
    """Axes of the transient ``H``. Axis 0 is time (``T_*``) or frequency (``F_*``)."""

    UNKNOWN = 0
    T_Sx_Sy = 1
    T_Lx_Ly_Sx_Sy = 2
    T_Si = 3
    T_Li_Si = 4
    F_Sx_Sy = 10
    F_Lx_Ly_Sx_Sy = 11
    F_Si = 12
    F_Li_Si = 13


class GridFormat(IntEnum):
    """Layout of a grid of wall points: a list ``(N, 3)`` or a grid ``(X, Y, 3)``."""

    UNKNOWN = 0
    N_3 = 1
    X_Y_3 = 2


class VolumeFormat(IntEnum):
    """Layout of a voxel volume (deprecated in y-tal, kept for file compatibility)."""

    UNKNOWN = 0
    N_3 = 1
    X_Y_Z_3 = 2
    X_Y_3 = 3


class CaptureKind(str, Enum):
    """How laser and sensor points are paired on the relay wall."""

    SINGLE_SPOT = "single_spot"
    """One laser spot, a grid of sensor points (the thesis setup)."""
    CONFOCAL = "confocal"
    """Laser and sensor scan the same points together."""
    EXHAUSTIVE = "exhaustive"
    """Every laser point with every sensor point."""

"""The shapes the datasets of y-tal's layout and of the Zaragoza (ZNLOS) layout may declare
(and a MATLAB confocal scan, :data:`SQUARE_SCAN`).

Each follows from the transient's own header (``H`` and its ``H_format``, or ``data``): a
point grid holds as many points of 3 coordinates as the transient's axes have sensor (or
laser) points, a device position 3 numbers, a bin width one number, a hidden volume's
centre, rotation or size 1 or 3 numbers. :func:`nlosfw.capture.hdf5.read_fields` checks
every dataset against them before it reads any (:class:`~nlosfw.common.hdf5_guard.Expected`),
so a small file declaring a huge dataset of another shape is refused from its header. A
dataset sized by a transient the file does not have is not read at all: the capture is
refused for the missing transient.
"""

from __future__ import annotations

import math

from nlosfw.capture.enums import HFormat
from nlosfw.capture.znlos_layout import data_order, data_transient_shape
from nlosfw.common.hdf5_guard import Expected, points, ranks, values

ONE = values(1, what="one number")
POINT = values(3, what="3 numbers (one point)")
#: The histograms of a confocal raster scan (MATLAB's order): [N, N, T].
SQUARE_SCAN = Expected("a square scan [N, N, T]",
                       lambda shape: len(shape) == 3 and shape[0] == shape[1])
#: A hidden volume's centre, rotation or size (a hint): 1 or 3 numbers.
VOLUME_HINT = values(1, 3, what="1 or 3 numbers (a hint about the hidden volume)")

#: The datasets whose shape does not depend on the transient.
FIXED: dict[str, Expected] = {
    "H_format": ONE, "sensor_grid_format": ONE, "laser_grid_format": ONE,
    "volume_format": ONE, "delta_t": ONE, "t_start": ONE,
    "t_accounts_first_and_last_bounces": ONE,
    "scene_info": values(1, what="one YAML text"),
    "sensor_xyz": POINT, "laser_xyz": POINT,
    "deltaT": ONE, "t0": ONE, "cameraPosition": POINT, "laserPosition": POINT,
    "hiddenVolumePosition": VOLUME_HINT, "hiddenVolumeRotation": VOLUME_HINT,
    "hiddenVolumeSize": VOLUME_HINT,
}


def h_axes(h_format: HFormat) -> tuple[str, ...]:
    """The axes of ``H`` after time (or frequency), from the format's name (``T_Lx_Ly_Sx_Sy``:
    Lx, Ly, Sx, Sy)."""
    return tuple(h_format.name.split("_")[1:])


def ytal_shapes(h_shape: tuple[int, ...], h_format: HFormat | None) -> dict[str, Expected]:
    """The shapes of ``H`` and of the point grids of y-tal's layout, for an ``H`` that
    declares ``h_shape`` in format ``h_format`` (None or UNKNOWN: not a format a capture
    can have; the grids are then bounded by H's points, and the format is refused)."""
    grids = ("sensor_grid_xyz", "sensor_grid_normals", "laser_grid_xyz", "laser_grid_normals")
    if h_format is None or h_format is HFormat.UNKNOWN:
        n = math.prod(h_shape[1:])
        bound = Expected(f"at most {n} points of 3 coordinates (H's points)",
                         lambda shape: len(shape) >= 1 and 3 in (shape[0], shape[-1])
                         and math.prod(shape) <= 3 * n)
        return {"H": ranks(2, 3, 5, what="2, 3 or 5 axes"), **dict.fromkeys(grids, bound)}
    axes = h_axes(h_format)
    rules = {"H": ranks(1 + len(axes), what=f"{1 + len(axes)} axes (H_format "
                                            f"{h_format.name})")}
    if len(h_shape) != 1 + len(axes):
        return rules                      # H is refused first; its grids are not read
    sizes = dict(zip(axes, h_shape[1:], strict=True))
    sensor_axes = [n for a, n in sizes.items() if a.startswith("S")]
    laser_axes = [n for a, n in sizes.items() if a.startswith("L")]
    sensors = math.prod(sensor_axes)
    sensor = points(sensors, what=f"{sensors} points of 3 coordinates, as many as H's "
                                  f"sensor axes {sensor_axes}")
    if laser_axes:
        lasers = math.prod(laser_axes)
        laser = points(lasers, what=f"{lasers} points of 3 coordinates, as many as H's "
                                    f"laser axes {laser_axes}")
    else:
        laser = points(1, sensors, what=f"one point of 3 coordinates (a single spot) or "
                                        f"{sensors} (confocal, H's sensor axes {sensor_axes})")
    return {**rules, "sensor_grid_xyz": sensor, "sensor_grid_normals": sensor,
            "laser_grid_xyz": laser, "laser_grid_normals": laser}


def znlos_shapes(data_shape: tuple[int, ...]) -> dict[str, Expected]:
    """The shapes of ``data`` and of the point grids of the Zaragoza layout, for a
    ``data`` that declares ``data_shape`` (grids stored as (3, ...))."""
    rules = {"data": Expected("5 (confocal) or 7 axes in a known ZNLOS order",
                              lambda shape: data_order(shape) is not None)}
    found = data_transient_shape(data_shape)
    if found is None:
        return rules                      # data is refused first; its grids are not read
    _, sensors, lasers = found
    camera = points(sensors, what=f"{sensors} points of 3 coordinates, as many as data's "
                                  "sensor points")
    laser = points(1, sensors, lasers, what=f"1, {sensors} or {lasers} points of 3 "
                                            "coordinates (data's laser points)")
    return {**rules, "cameraGridPositions": camera, "cameraGridNormals": camera,
            "laserGridPositions": laser, "laserGridNormals": laser}

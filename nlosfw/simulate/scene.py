"""Scene descriptions: relay wall, capture setup, time axis, hidden geometry, noise.

A :class:`Scene` is what every :class:`~nlosfw.simulate.Simulator` renders.
It is built from the ``scene`` Hydra config group with
:func:`scene_from_config`, which checks every option by name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nlosfw.capture.geometry import device_legs
from nlosfw.common.config import Choice, config_from_mapping, require, require_finite

#: Geometry item types understood by :mod:`nlosfw.simulate.geometry`.
GEOMETRY_TYPES = ("rectangle", "box", "mesh", "patch", "point", "heightfield")


@dataclass(frozen=True)
class WallConfig:
    """The relay wall: a rectangle in the plane z = 0 facing +z."""

    size: tuple[float, float] = (2.0, 2.0)
    """[m] Extent along x and y."""
    resolution: tuple[int, int] = (64, 64)
    """Number of sensor points along x and y (cell-centred)."""
    center: tuple[float, float] = (0.0, 0.0)
    """[m] Centre of the wall (x, y)."""

    def __post_init__(self) -> None:
        require_finite(self)
        require(all(s > 0 for s in self.size), "size", f"must be > 0 metres, got {self.size}")
        require(all(r >= 1 for r in self.resolution), "resolution",
                f"must be >= 1 sensor per axis, got {self.resolution}")

    @property
    def spacing(self) -> tuple[float, float]:
        """Sensor spacing (dx, dy) in metres."""
        return (self.size[0] / self.resolution[0], self.size[1] / self.resolution[1])

    def grid_xyz(self) -> np.ndarray:
        """Cell-centred sensor points, shape (X, Y, 3) as in y-tal's ``X_Y_3``."""
        nx, ny = self.resolution
        dx, dy = self.spacing
        xs = self.center[0] - self.size[0] / 2 + (np.arange(nx) + 0.5) * dx
        ys = self.center[1] - self.size[1] / 2 + (np.arange(ny) + 0.5) * dy
        x, y = np.meshgrid(xs, ys, indexing="ij")
        return np.stack([x, y, np.zeros_like(x)], axis=-1)


class CaptureType(Choice):
    """One laser spot and a grid of sensor points, or laser and sensor at each point."""

    single_spot = "single_spot"
    confocal = "confocal"


@dataclass(frozen=True)
class CaptureSetup:
    """Where the laser hits the wall and where the devices are."""

    type: CaptureType = CaptureType.single_spot
    """``single_spot``: one laser spot and a grid of sensor points; ``confocal``: laser and
    sensor at each point."""
    laser_spot: tuple[float, float] = (0.0, 0.0)
    """[m] Laser spot (x, y) on the wall for single-spot captures."""
    laser_position: tuple[float, float, float] = (-0.5, 0.0, 0.25)
    """[m] Position of the laser device."""
    sensor_position: tuple[float, float, float] = (-0.5, 0.0, 0.25)
    """[m] Position of the sensor device."""
    device_legs: bool = False
    """Count the device-to-wall legs in the time axis (t_accounts_first_and_last_bounces)."""

    def __post_init__(self) -> None:
        require_finite(self)
        require(self.laser_position[2] > 0, "laser_position",
                "must be in front of the wall (z > 0)")
        require(self.sensor_position[2] > 0, "sensor_position",
                "must be in front of the wall (z > 0)")


@dataclass(frozen=True)
class TimeAxis:
    """Histogram bins of optical path length."""

    bins: int = 2048
    """Number of time bins."""
    bin_width: float = 0.003
    """[m] Width of a bin in optical path length (c times its duration)."""
    start: float = 0.0
    """[m] Optical path length at the start of the first bin."""

    def __post_init__(self) -> None:
        require_finite(self)
        require(self.bins > 0, "bins", f"must be a positive number of bins, got {self.bins}")
        require(self.bin_width > 0, "bin_width",
                f"must be a positive number of metres, got {self.bin_width}")

    @property
    def end(self) -> float:
        return self.start + self.bins * self.bin_width


@dataclass(frozen=True)
class GeometryItem:
    """One hidden object. Rectangles and patches face the wall (normal -z) before rotation."""

    type: str = "rectangle"
    """One of rectangle, box, mesh, patch, point, heightfield."""
    position: tuple[float, float, float] = (0.0, 0.0, 1.0)
    """[m] Centre of the item."""
    size: tuple[float, ...] = (0.5, 0.5)
    """rectangle/patch/heightfield: (width, height); box: (width, height, depth); mesh: ignored."""
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """[deg] Rotation about x, then y, then z, around the item's centre."""
    albedo: float = 1.0
    """Diffuse albedo in [0, 1]; for a point, its effective scattering area (m^2)."""
    path: str | None = None
    """Mesh file (OBJ, PLY, STL, ...) for type mesh."""
    scale: float = 1.0
    """Uniform scale of a mesh file's coordinates."""
    params: dict[str, Any] = field(default_factory=dict)
    """Shape-specific parameters (e.g. a heightfield's bumps)."""
    lobe: float = 0.0
    """Exponent k of a glossy lobe about the surface normal: the BRDF is rho / pi times
    cos^k of the half vector's angle (0: Lambertian; :mod:`nlosfw.simulate.physics`)."""

    def __post_init__(self) -> None:
        require_finite(self)
        require(self.type in GEOMETRY_TYPES, "type",
                f"unknown geometry type {self.type!r}; valid: {', '.join(GEOMETRY_TYPES)}")
        require(self.albedo >= 0, "albedo", f"must be >= 0, got {self.albedo}")
        require(self.scale > 0, "scale", f"must be > 0, got {self.scale}")
        require(self.lobe >= 0, "lobe", f"must be >= 0 (0: Lambertian), got {self.lobe}")
        require(self.type != "point" or self.lobe == 0, "lobe",
                "a point scatterer has no normal to hold a lobe about; valid: 0")
        if self.type in ("rectangle", "patch", "heightfield"):
            require(len(self.size) == 2 and all(s > 0 for s in self.size), "size",
                    f"a {self.type} needs (width, height) > 0, got {self.size}")
        if self.type == "box":
            require(len(self.size) == 3 and all(s > 0 for s in self.size), "size",
                    f"a box needs (width, height, depth) > 0, got {self.size}")
        if self.type == "mesh":
            require(bool(self.path), "path", "a mesh item needs the path of a mesh file")
        require(self.type == "heightfield" or not self.params, "params",
                f"only heightfield items take params; a {self.type} has none")


class NoiseModel(Choice):
    """No photon noise, or Poisson photon counts."""

    none = "none"
    poisson = "poisson"


#: The most photons a simulated capture may expect in all (signal and dark counts): its
#: counts stay exact integers (below 2^53, as count splitting needs them) and within what
#: numpy's Poisson sampler draws (1e19 ended the capture stage in "lam value too large").
MAX_EXPECTED_PHOTONS = 1e15
#: The most laser pulses per scan point (numpy's multinomial draw takes a 64-bit integer).
MAX_PULSES = 2**63 - 1


@dataclass(frozen=True)
class NoiseConfig:
    """Measurement noise applied after rendering (see :mod:`nlosfw.simulate.noise`)."""

    model: NoiseModel = NoiseModel.none
    """``none`` or ``poisson`` photon counts."""
    photons: float = 1e6
    """Expected number of signal photons in the whole capture (poisson)."""
    dark_counts: float = 0.0
    """Expected dark counts per sensor over the whole time window (poisson)."""
    jitter_ps: float = 0.0
    """[ps] Standard deviation of Gaussian timing jitter (any model)."""
    pulses: int | None = None
    """Laser pulses per scan point (poisson): the detector records at most the first
    photon of each (pile-up); ``photons`` are those reaching it. null: an ideal detector."""

    def __post_init__(self) -> None:
        require_finite(self)
        require(self.pulses is None or 1 <= self.pulses <= MAX_PULSES, "pulses",
                f"must be >= 1 and at most {MAX_PULSES} (2^63 - 1), or null, got "
                f"{self.pulses}")
        require(self.pulses is None or self.model == NoiseModel.poisson, "pulses",
                "a detector's pile-up needs photon counts: set model poisson, or pulses null")
        require(0 < self.photons <= MAX_EXPECTED_PHOTONS, "photons",
                f"must be > 0 and at most {MAX_EXPECTED_PHOTONS:g}, got {self.photons}")
        require(0 <= self.dark_counts <= MAX_EXPECTED_PHOTONS, "dark_counts",
                f"must be 0 to {MAX_EXPECTED_PHOTONS:g}, got {self.dark_counts}")
        require(self.jitter_ps >= 0, "jitter_ps", f"must be >= 0, got {self.jitter_ps}")


@dataclass(frozen=True)
class Scene:
    """Everything a simulator needs to produce a :class:`~nlosfw.capture.Capture`."""

    name: str = "custom"
    """The scene's name (recorded in metrics.json and figure titles)."""
    wall: WallConfig = field(default_factory=WallConfig)
    """The relay wall and its sensor grid."""
    capture: CaptureSetup = field(default_factory=CaptureSetup)
    """Laser spot, devices and capture type."""
    time: TimeAxis = field(default_factory=TimeAxis)
    """The histogram's time axis."""
    geometry: tuple[GeometryItem, ...] = ()
    """The hidden objects."""
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    """Measurement noise added after rendering."""
    ground_truth_resolution: tuple[int, int] | None = None
    """Resolution (x, y) of the ground-truth maps; default the sensor grid's."""

    def __post_init__(self) -> None:
        require(len(self.geometry) > 0, "geometry", "the hidden scene needs at least one item")
        if self.noise.model == NoiseModel.poisson:
            sensors = math.prod(self.wall.resolution)
            dark = self.noise.dark_counts * sensors
            require(self.noise.photons + dark <= MAX_EXPECTED_PHOTONS, "noise.dark_counts",
                    f"{self.noise.dark_counts:g} per sensor over {sensors} sensors and "
                    f"{self.noise.photons:g} signal photons expect more than "
                    f"{MAX_EXPECTED_PHOTONS:g} photons in all")

    @property
    def is_confocal(self) -> bool:
        return self.capture.type == "confocal"

    def laser_spot_xyz(self) -> np.ndarray:
        """The single laser spot on the wall (3,)."""
        return np.array([self.capture.laser_spot[0], self.capture.laser_spot[1], 0.0])

    def device_path(self, wall_points: np.ndarray) -> np.ndarray:
        """Device legs (...) of light measured at ``wall_points`` (..., 3), in metres.

        Zero unless the time axis counts them (``capture.device_legs``); the
        laser leg ends at the laser spot, or at the wall point for confocal scans.
        """
        points = np.asarray(wall_points, dtype=float)
        if not self.capture.device_legs:
            return np.zeros(points.shape[:-1])
        laser = points if self.is_confocal else self.laser_spot_xyz()
        return device_legs(laser, points, np.asarray(self.capture.laser_position, dtype=float),
                           np.asarray(self.capture.sensor_position, dtype=float))


def scene_from_config(mapping: Any, where: str = "scene") -> Scene:
    """Build and validate a :class:`Scene` from a plain mapping (e.g. Hydra's ``cfg.scene``)."""
    return config_from_mapping(Scene, mapping, where)

"""Tiny, fast fixtures shared by the conformance checks and the test suites.

Everything here is computed in closed form or with the ``analytic`` simulator,
so fixtures never depend on the plugin under test.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.image.reconstruction import volume_voxels
from nlosfw.simulate.geometry import validate_scene
from nlosfw.simulate.interface import Simulator
from nlosfw.simulate.scene import Scene, scene_from_config
from nlosfw.transform.field import PhasorField

#: Position of the hidden patch of :func:`tiny_scene` (m).
TINY_TARGET = (0.1, -0.05, 0.6)


def tiny_scene_config(confocal: bool = False, resolution: int = 8, bins: int = 256,
                      bin_width: float = 0.01, device_legs: bool = False,
                      target: tuple[float, float, float] = TINY_TARGET,
                      patch: float = 0.04) -> dict[str, Any]:
    """Plain config of a 1 m wall, ``resolution``^2 sensors and one small patch facing the wall."""
    return {
        "name": "tiny",
        "wall": {"size": [1.0, 1.0], "resolution": [resolution, resolution]},
        "capture": {"type": "confocal" if confocal else "single_spot",
                    "device_legs": device_legs},
        "time": {"bins": bins, "bin_width": bin_width, "start": 0.0},
        "geometry": [{"type": "patch", "position": list(target), "size": [patch, patch]}],
    }


def tiny_scene(**kwargs: Any) -> Scene:
    """The :func:`tiny_scene_config` as a validated :class:`Scene`."""
    return scene_from_config(tiny_scene_config(**kwargs))


def tiny_capture(**kwargs: Any) -> Capture:
    """The analytic transient of :func:`tiny_scene` (no noise)."""
    from nlosfw.simulate.analytic import AnalyticSimulator

    return AnalyticSimulator().simulate(tiny_scene(**kwargs))


def wall_grid(n: int = 16, size: float = 1.0) -> np.ndarray:
    """Cell-centred wall points (Y, X, 3) of an n x n grid on a ``size`` m wall in z = 0."""
    return rect_wall_grid((n, n), size / n)


def point_phasor_field(target: tuple[float, float, float] = TINY_TARGET, n: int = 16,
                       size: float = 1.0, frequencies: npt.ArrayLike = (4.0,),
                       confocal: bool = False) -> PhasorField:
    """Exact phasor field of one point scatterer on the n x n :func:`wall_grid` of ``size``.

    P_f(x_s) = exp(-2 pi i f d) / (r_l^2 r_s^2) with d the laser -> point -> sensor
    path, the wall's cosine factors included, laser spot at the wall centre
    (:func:`point_field` on a square grid, without device legs).
    """
    return point_field(target, (n, n), size / n, frequencies, confocal=confocal)


def smooth_field(n: int = 16, frequencies: npt.ArrayLike | None = None, seed: int = 0,
                 n_waves: int = 3) -> PhasorField:
    """A smooth synthetic complex field: a sum of a few plane waves over (x, y, f).

    Spatial wavelengths stay above 4 grid spacings so the field is resolvable.
    """
    rng = np.random.default_rng(seed)
    f = np.linspace(2.0, 4.0, 12) if frequencies is None else np.asarray(frequencies, float)
    wall = wall_grid(n)
    x, y = wall[..., 0][None], wall[..., 1][None]
    ff = f[:, None, None]
    values = np.zeros((f.size, n, n), dtype=np.complex128)
    k_max = 2 * np.pi / (4 * (1.0 / n))
    for _ in range(n_waves):
        kx, ky = rng.uniform(-0.5, 0.5, 2) * k_max
        kf = rng.uniform(0.5, 2.0)
        amp = rng.uniform(0.5, 1.0) * np.exp(2j * np.pi * rng.random())
        values += amp * np.exp(1j * (kx * x + ky * y + kf * ff))
    return PhasorField(values=values, frequencies=f, wall_xyz=wall,
                       geometry=CaptureGeometry(kind=CaptureKind.SINGLE_SPOT,
                                                laser_point=np.zeros(3)))


def tiny_voxels(depths: npt.ArrayLike = (0.5, 0.6, 0.7), n: int = 16, size: float = 1.0
                ) -> np.ndarray:
    """A small stack of planes (Z, Y, X, 3) facing the wall, matching :func:`wall_grid`."""
    return volume_voxels(depths, (-size / 2, size / 2), (-size / 2, size / 2), (n, n))


# --------------------------------------------------------------------------- non-square grids
#: Laser and sensor device positions of the fixtures that keep the device legs (m).
DEVICE_XYZ = (-0.6, 0.1, 0.3)


def rect_wall_grid(shape: tuple[int, int] = (6, 8), spacing: float = 0.1,
                   center: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Cell-centred wall points (Y, X, 3) of a ``shape`` = (ny, nx) grid of ``spacing``."""
    ny, nx = shape
    xs = center[0] + (np.arange(nx) - (nx - 1) / 2) * spacing
    ys = center[1] + (np.arange(ny) - (ny - 1) / 2) * spacing
    y, x = np.meshgrid(ys, xs, indexing="ij")
    return np.stack([x, y, np.zeros_like(x)], axis=-1)


def point_field(target: tuple[float, float, float], shape: tuple[int, int] = (12, 16),
                spacing: float = 1 / 16, frequencies: npt.ArrayLike = (4.0,),
                weights: npt.ArrayLike | None = None,
                confocal: bool = False, device_legs: bool = False) -> PhasorField:
    """Exact phasor field of a point scatterer on a (ny, nx) wall grid.

    P_f(x_s) = A(x_s) exp(-2 pi i f (r_l + r_s + legs(x_s))), laser spot at the
    wall centre (single spot) or at x_s (confocal). With ``device_legs`` the
    phase keeps the device legs to :data:`DEVICE_XYZ` and the geometry says so.
    """
    wall = rect_wall_grid(shape, spacing)
    p = np.asarray(target, dtype=float)
    r_s = np.linalg.norm(wall - p, axis=-1)
    device = np.asarray(DEVICE_XYZ, dtype=float)
    if confocal:
        r_l = r_s
        legs = 2 * np.linalg.norm(wall - device, axis=-1)
        geometry = CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=device,
                                   sensor_xyz=device, t_accounts_first_and_last_bounces=device_legs)
    else:
        laser = np.zeros(3)
        r_l = np.full_like(r_s, np.linalg.norm(p - laser))
        legs = np.linalg.norm(wall - device, axis=-1) + np.linalg.norm(laser - device)
        geometry = CaptureGeometry(kind=CaptureKind.SINGLE_SPOT, laser_point=laser,
                                   laser_xyz=device, sensor_xyz=device,
                                   t_accounts_first_and_last_bounces=device_legs)
    if not device_legs:
        legs = np.zeros_like(r_s)
    amp = (p[2] / r_l) * (p[2] / r_s) / (r_l**2 * r_s**2)
    f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    values = amp[None] * np.exp(-2j * np.pi * f[:, None, None] * (r_l + r_s + legs)[None])
    return PhasorField(values=values, frequencies=f, wall_xyz=wall, geometry=geometry,
                       weights=None if weights is None else np.asarray(weights),
                       metadata={"target": [float(v) for v in p]})


def gaussian_band(centre: float, sigma_f: float, n: int = 9,
                  width: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, weights): ``n`` frequencies over centre ± width*sigma_f, Gaussian weights."""
    f = np.linspace(centre - width * sigma_f, centre + width * sigma_f, n)
    w = np.exp(-0.5 * ((f - centre) / sigma_f) ** 2) * (f[1] - f[0] if n > 1 else 1.0)
    return f, w.astype(np.complex128)


def volume_inputs(shape: tuple[int, int, int] = (4, 23, 31), seed: int = 2
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a neural volume's network pass takes, drawn at random, the same for every
    backend, float32: (coords (Z Y X, 3) in [-0.9, 0.9], gain (Z, Y, X) in [0.5, 2],
    weights (Z, Y, X) standard normal, to differentiate a weighted sum of the albedo)."""
    rng = np.random.default_rng(seed)
    coords = rng.uniform(-0.9, 0.9, (int(np.prod(shape)), 3)).astype(np.float32)
    gain = rng.uniform(0.5, 2.0, shape).astype(np.float32)
    return coords, gain, rng.normal(size=shape).astype(np.float32)


def aligned_voxels(wall: np.ndarray, depths: npt.ArrayLike) -> np.ndarray:
    """Planes (Z, Y, X, 3) at ``depths`` whose (x, y) are exactly the wall points (Y, X, 3)."""
    depths = np.atleast_1d(np.asarray(depths, dtype=float))
    vox = np.repeat(np.asarray(wall, dtype=float)[None], depths.size, axis=0)
    vox[..., 2] = depths[:, None, None]
    return vox


def point_scene_config(target: tuple[float, float, float] = (0.1, -0.05, 0.5),
                       resolution: tuple[int, int] = (8, 6), size: tuple[float, float] = (0.8, 0.6),
                       confocal: bool = False, device_legs: bool = False, bins: int = 400,
                       bin_width: float = 0.01, start: float = 0.0) -> dict[str, Any]:
    """Plain config of a non-square wall ((nx, ny) = ``resolution``) and one point scatterer."""
    return {
        "name": "point",
        "wall": {"size": list(size), "resolution": list(resolution)},
        "capture": {"type": "confocal" if confocal else "single_spot",
                    "device_legs": device_legs, "laser_position": list(DEVICE_XYZ),
                    "sensor_position": list(DEVICE_XYZ)},
        "time": {"bins": bins, "bin_width": bin_width, "start": start},
        "geometry": [{"type": "point", "position": list(target), "albedo": 1e-3}],
    }


def point_capture(**kwargs: Any) -> Capture:
    """The analytic transient of :func:`point_scene_config` (one bin per sensor, no noise)."""
    from nlosfw.simulate.analytic import AnalyticSimulator

    return AnalyticSimulator().simulate(scene_from_config(point_scene_config(**kwargs)))


def random_capture(seed: int = 0, **kwargs: Any) -> Capture:
    """:func:`point_capture`'s geometry with uniform random float32 values in H."""
    capture = point_capture(**kwargs)
    rng = np.random.default_rng(seed)
    return capture.replace(H=rng.random(capture.H.shape, dtype=np.float32),
                           scene_info={})


def exhaustive_capture() -> Capture:
    """A tiny exhaustive capture (T_Lx_Ly_Sx_Sy): every laser point with every sensor."""
    from nlosfw.capture.enums import GridFormat, HFormat

    grid = np.moveaxis(rect_wall_grid((2, 3), 0.2), 0, 1)     # (X, Y, 3)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), grid.shape).copy()
    H = np.zeros((16, 3, 2, 3, 2), dtype=np.float32)
    H[5] = 1.0
    return Capture(H=H, H_format=HFormat.T_Lx_Ly_Sx_Sy, sensor_grid_xyz=grid,
                   sensor_grid_normals=normals, sensor_grid_format=GridFormat.X_Y_3,
                   laser_grid_xyz=grid, laser_grid_normals=normals,
                   laser_grid_format=GridFormat.X_Y_3, sensor_xyz=np.array(DEVICE_XYZ),
                   laser_xyz=np.array(DEVICE_XYZ), delta_t=0.05, t_start=0.0,
                   t_accounts_first_and_last_bounces=False)


# --------------------------------------------------------------------------- simulator tests
def scene_with(geometry: list[dict[str, Any]], resolution: tuple[int, int] = (12, 10),
               bins: int = 400, bin_width: float = 0.01, **capture: Any) -> Scene:
    """A 1 m wall of ``resolution`` = (nx, ny) sensors seeing ``geometry`` (items as in YAML).

    ``capture`` updates the capture block of :func:`tiny_scene_config` (for
    example ``type="confocal"``, ``device_legs=True``).
    """
    config = tiny_scene_config(bins=bins, bin_width=bin_width)
    config["wall"]["resolution"] = list(resolution)
    config["capture"].update(capture)
    config["geometry"] = geometry
    return scene_from_config(config)


def rendered(simulator: Simulator, scene: Scene) -> Capture:
    """The noise-free transient of ``scene`` (validated first, as ``simulate()`` does)."""
    return simulator.render(validate_scene(scene))


def relative_l2(a: np.ndarray, b: np.ndarray) -> float:
    """||a - b|| / ||b|| over all entries, in float64."""
    b = np.asarray(b, dtype=float)
    return float(np.linalg.norm(np.asarray(a, dtype=float) - b) / np.linalg.norm(b))


def heldout_error_db(predicted: np.ndarray, truth: np.ndarray, held: np.ndarray) -> float:
    """The error of ``predicted`` against ``truth`` (both (F, Y, X)) at the wall points where
    ``held`` (Y, X) is True, every frequency: 10 log10(sum |p - t|^2 / sum |t|^2), in dB."""
    held = np.asarray(held, dtype=bool)
    miss = np.asarray(predicted)[:, held] - np.asarray(truth)[:, held]
    power = float(np.sum(np.abs(np.asarray(truth)[:, held]) ** 2))
    return float(10 * np.log10(float(np.sum(np.abs(miss) ** 2)) / power))


class Agreement(NamedTuple):
    """How a transient compares with a reference transient of the same scene."""

    total: float
    """Total energy over the reference's."""
    worst_sensor: float
    """Largest |sensor energy / reference sensor energy - 1|."""
    relative_l2: float
    """:func:`relative_l2` of the whole transients."""


def analytic_agreement(simulator: Simulator, scene: Scene,
                       patch_size: float = 0.003) -> Agreement:
    """Compare ``simulator``'s transient of ``scene`` with the ``analytic`` simulator's.

    For occlusion-free scenes, where both follow the same radiometric convention,
    bins and sensor order; ``patch_size`` is the analytic simulator's quadrature cell.
    """
    from nlosfw.simulate.analytic import AnalyticSimulator

    reference = rendered(AnalyticSimulator({"patch_size": patch_size}), scene).H.astype(float)
    H = rendered(simulator, scene).H.astype(float)
    per_sensor = H.sum(axis=0) / reference.sum(axis=0)                  # (nx, ny)
    return Agreement(total=float(H.sum() / reference.sum()),
                     worst_sensor=float(np.abs(per_sensor - 1).max()),
                     relative_l2=relative_l2(H, reference))

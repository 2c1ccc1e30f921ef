"""Tiny, fast fixtures shared by the conformance checks and the test suites.

Everything here is computed in closed form or with the ``analytic`` simulator,
so fixtures never depend on the plugin under test.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nlosfw.capture import Capture, CaptureGeometry
from nlosfw.enums import CaptureKind
from nlosfw.phasor_field import PhasorField
from nlosfw.reconstruction import volume_voxels
from nlosfw.scene import Scene, scene_from_config

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
    from nlosfw.builtin.analytic import AnalyticSimulator

    return AnalyticSimulator().simulate(tiny_scene(**kwargs))


def wall_grid(n: int = 16, size: float = 1.0) -> np.ndarray:
    """Cell-centred wall points (Y, X, 3) in the plane z = 0."""
    c = -size / 2 + (np.arange(n) + 0.5) * size / n
    y, x = np.meshgrid(c, c, indexing="ij")
    return np.stack([x, y, np.zeros_like(x)], axis=-1)


def point_phasor_field(target: tuple[float, float, float] = TINY_TARGET, n: int = 16,
                       size: float = 1.0, frequencies: Any = (4.0,),
                       confocal: bool = False) -> PhasorField:
    """Exact phasor field of one point scatterer (the transform of its three-bounce transient).

    P_f(x_s) = exp(-2 pi i f d) / (r_l^2 r_s^2) with d the laser -> point -> sensor
    path, the wall's cosine factors included, laser spot at the wall centre.
    """
    wall = wall_grid(n, size)
    p = np.asarray(target, dtype=float)
    r_s = np.linalg.norm(wall - p, axis=-1)
    if confocal:
        r_l = r_s
        geometry = CaptureGeometry(kind=CaptureKind.CONFOCAL)
    else:
        laser = np.zeros(3)
        r_l = np.full_like(r_s, np.linalg.norm(p - laser))
        geometry = CaptureGeometry(kind=CaptureKind.SINGLE_SPOT, laser_point=laser)
    amp = (p[2] / r_l) * (p[2] / r_s) / (r_l**2 * r_s**2)
    f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    values = amp[None] * np.exp(-2j * np.pi * f[:, None, None] * (r_l + r_s)[None])
    return PhasorField(values=values.astype(np.complex128), frequencies=f, wall_xyz=wall,
                       geometry=geometry, metadata={"target": list(target)})


def smooth_field(n: int = 16, frequencies: Any = None, seed: int = 0,
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


def tiny_voxels(depths: Any = (0.5, 0.6, 0.7), n: int = 16, size: float = 1.0) -> np.ndarray:
    """A small stack of planes (Z, Y, X, 3) facing the wall, matching :func:`wall_grid`."""
    return volume_voxels(depths, (-size / 2, size / 2), (-size / 2, size / 2), (n, n))

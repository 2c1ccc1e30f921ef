"""Brute-force references the conformance checks compare against.

Written as plainly as possible, straight from the formulas (DOMAIN.md §2), and
sharing no code with the plugins under test. Slow: use them on tiny inputs.

Conventions: P_f(x_s) = sum_t H(x_s, t) exp(-2 pi i f t_c) delta_t with t_c the
bin centres; a voxel x_v is imaged as
|sum_f w_f L_f(x_v) sum_s P_f(x_s) exp(2 pi i f (m |x_v - x_s| + legs(x_s))) / |x_v - x_s||^2
with m = 1 and L_f = exp(2 pi i f |x_v - x_l|) for a single laser spot x_l,
m = 2 and L_f = 1 for confocal scans.
"""

from __future__ import annotations

import math

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import DataError
from nlosfw.transform.field import PhasorField


def naive_dft(H: np.ndarray, t_start: float, delta_t: float,
              frequencies: np.ndarray) -> np.ndarray:
    """P[f, ...] = sum_i H[i, ...] exp(-2 pi i f (t_start + (i + 1/2) delta_t)) delta_t."""
    H = np.asarray(H, dtype=np.float64)
    out = np.zeros((len(frequencies),) + H.shape[1:], dtype=np.complex128)
    for k, f in enumerate(frequencies):
        for i in range(H.shape[0]):
            t = t_start + (i + 0.5) * delta_t
            out[k] += H[i] * np.exp(-2j * np.pi * f * t) * delta_t
    return out


def naive_capture_field(capture: Capture, frequencies: np.ndarray) -> np.ndarray:
    """The expected field values (F, Y, X) of a (T, X, Y) capture, device legs kept."""
    P = naive_dft(capture.H, capture.t_start, capture.delta_t, frequencies)   # (F, X, Y)
    if P.ndim == 2:                                                            # (F, N) list
        return P[:, None, :]
    return np.transpose(P, (0, 2, 1))


def device_legs(geometry: CaptureGeometry, wall_points: np.ndarray) -> np.ndarray:
    """|laser device - laser spot| + |sensor point - sensor device| for each wall point."""
    pts = np.asarray(wall_points, dtype=float)
    if not geometry.t_accounts_first_and_last_bounces:
        return np.zeros(pts.shape[:-1])
    sensor, laser = _point(geometry.sensor_xyz), _point(geometry.laser_xyz)
    out = np.zeros(pts.shape[:-1])
    for idx in np.ndindex(*pts.shape[:-1]):
        p = pts[idx]
        leg_s = math.dist(p, sensor)
        spot = p if geometry.kind is CaptureKind.CONFOCAL else _point(geometry.laser_point)
        out[idx] = leg_s + math.dist(spot, laser)
    return out


def _point(xyz: np.ndarray | None) -> np.ndarray:
    """A position the reference needs; DataError when the geometry lacks it."""
    if xyz is None:
        raise DataError("the capture geometry lacks a position the reference needs")
    return np.asarray(xyz, dtype=float)


def naive_rsd(field: PhasorField, voxels: np.ndarray, time: float = 0.0) -> np.ndarray:
    """Coherent image of ``field`` at ``voxels`` (..., 3), one voxel at a time."""
    vox = np.asarray(voxels, dtype=float)
    wall = field.wall_xyz.reshape(-1, 3)
    values = field.values.reshape(field.n_frequencies, -1)
    legs = device_legs(field.geometry, field.wall_xyz).reshape(-1)
    weights = field.effective_weights
    confocal = field.geometry.kind is CaptureKind.CONFOCAL
    out = np.zeros(vox.shape[:-1])
    for idx in np.ndindex(*vox.shape[:-1]):
        v = vox[idx]
        total = 0j
        for k, f in enumerate(field.frequencies):
            u = 0j
            for s in range(wall.shape[0]):
                r = math.dist(v, wall[s])
                path = (2 * r if confocal else r) + legs[s]
                u += values[k, s] * np.exp(2j * np.pi * f * path) / r
            if not confocal:
                u *= np.exp(2j * np.pi * f * math.dist(v, _point(field.geometry.laser_point)))
            total += weights[k] * np.exp(2j * np.pi * f * time) * u
        out[idx] = abs(total) ** 2
    return out


def gaussian_pulse_spectrum(frequencies: np.ndarray, wavelength: float, sigma: float,
                            n_quadrature: int = 20001) -> np.ndarray:
    """∫ exp(-t^2/(2 sigma^2)) exp(2 pi i t / wavelength) exp(-2 pi i f t) dt by quadrature.

    A Riemann sum over ±12 sigma (the Gaussian is below 1e-31 there), independent
    of the closed form sqrt(2 pi) sigma exp(-2 pi^2 sigma^2 (f - 1/wavelength)^2).
    """
    t = np.linspace(-12 * sigma, 12 * sigma, n_quadrature)
    dt = t[1] - t[0]
    pulse = np.exp(-t**2 / (2 * sigma**2)) * np.exp(2j * np.pi * t / wavelength)
    return np.array([np.sum(pulse * np.exp(-2j * np.pi * f * t)) * dt for f in frequencies])


def normalised_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two images (1 = identical up to gain and offset)."""
    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    a = a - a.mean()
    b = b - b.mean()
    denom = np.sqrt(np.dot(a, a) * np.dot(b, b))
    return float(np.dot(a, b) / denom) if denom > 0 else 0.0

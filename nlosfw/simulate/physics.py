"""Three-bounce light transport through the hidden scene: path lengths and weights.

The one radiometric convention of nlosfw (every simulator follows it so their
captures are interchangeable): unit laser power reaches the wall spot x_l;
the relay wall is Lambertian with albedo 1; a hidden surface element dA at p
with normal n_p is Lambertian with albedo rho; ``H`` holds the radiance leaving
the wall point x_s, binned by optical path length. One path then contributes

    rho * dA * cos_l * cos_p_in * cos_p_out * cos_s / (pi^3 * r_l^2 * r_s^2)

with r_l = |p - x_l|, r_s = |p - x_s|, cos_l and cos_s the cosines at the wall
between its normal (+z) and the hidden point, cos_p_in and cos_p_out the
cosines at p. Surfaces are two-sided: a path counts when x_l and x_s are on
the same side of the surface. A point scatterer has no normal: its cosines at
p are dropped and ``rho * dA`` is its effective area (the ``albedo`` of a
``point`` item). Confocal scans use x_l = x_s.

A glossy surface (an item's ``lobe`` exponent k > 0) multiplies its Lambertian BRDF
rho / pi by cos^k(theta_h), theta_h the angle between its normal and the half vector of
the directions from p to x_l and to x_s: a lobe about the normal, equal to the Lambertian
value where the half vector is the normal (for a confocal scan, the point seen head on).
"""

from __future__ import annotations

import numpy as np

_INV_PI3 = 1.0 / np.pi**3


def three_bounce(
    laser_points: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray | None,
    area_albedo: np.ndarray,
    sensor_points: np.ndarray,
    lobe: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Path length and weight of laser -> hidden point -> sensor, without visibility.

    ``laser_points`` is (3,) for a single spot or (S, 3) paired with the sensors
    (confocal). ``points`` (P, 3) with ``normals`` (P, 3) or None for point
    scatterers; ``area_albedo`` (P,) is rho * dA; ``lobe`` (P,) the lobe exponents of
    points with normals (None: all Lambertian). Returns two (P, S) arrays:
    the hidden part of the optical path |x_l - p| + |p - x_s| and the weight.
    """
    points = np.asarray(points, dtype=float)
    sensors = np.asarray(sensor_points, dtype=float)
    laser = np.asarray(laser_points, dtype=float)
    # components of p -> x_s and p -> x_l, broadcast to (P, S) or (P, 1)
    d_s = [sensors[None, :, k] - points[:, None, k] for k in range(3)]
    if laser.ndim == 1:
        d_l = [laser[k] - points[:, None, k] for k in range(3)]
    else:
        d_l = [laser[None, :, k] - points[:, None, k] for k in range(3)]
    r_s = np.sqrt(d_s[0] ** 2 + d_s[1] ** 2 + d_s[2] ** 2)
    r_l = np.sqrt(d_l[0] ** 2 + d_l[1] ** 2 + d_l[2] ** 2)
    # cosines at the wall (the plane z = 0, normal +z) between its normal and the direction to p
    cos_s = -d_s[2] / r_s
    cos_l = -d_l[2] / r_l
    weight = np.maximum(cos_l, 0.0) * np.maximum(cos_s, 0.0)
    if normals is not None:
        n = np.asarray(normals, dtype=float)
        cos_in = (d_l[0] * n[:, None, 0] + d_l[1] * n[:, None, 1] + d_l[2] * n[:, None, 2]) / r_l
        cos_out = (d_s[0] * n[:, None, 0] + d_s[1] * n[:, None, 1]
                   + d_s[2] * n[:, None, 2]) / r_s
        both = cos_in * cos_out                       # > 0: x_l and x_s on the same side
        weight = weight * np.maximum(both, 0.0)
        if lobe is not None:
            half = [d_l[k] / r_l + d_s[k] / r_s for k in range(3)]
            cos_h = np.abs(half[0] * n[:, None, 0] + half[1] * n[:, None, 1]
                           + half[2] * n[:, None, 2]) / np.sqrt(
                half[0] ** 2 + half[1] ** 2 + half[2] ** 2)
            weight = weight * cos_h ** np.asarray(lobe, dtype=float)[:, None]
    scale = np.asarray(area_albedo, dtype=float)[:, None] * _INV_PI3
    weight = weight * scale / ((r_l * r_s) ** 2)
    return r_l + r_s, weight



def bin_index(path: np.ndarray, t_start: float, delta_t: float) -> np.ndarray:
    """Index of the histogram bin holding each optical path length (may be out of range)."""
    return np.floor((np.asarray(path) - t_start) / delta_t).astype(np.int64)

"""The Rayleigh-Sommerfeld propagation kernel: ONE definition for every nlosfw imager.

With the transform convention P_f ∝ exp(-2 pi i f d) for a scatterer at path d
(f in cycles per metre of optical path), the field at voxel x_v is (thesis
eq. 3.13-3.15 with the lens phase matching our Fourier sign)

    U_f(x_v) = L_f(x_v) * sum_s P'_f(x_s) * exp(+2 pi i f m r_s) / r_s,   r_s = |x_v - x_s|

* m = 1 for a single laser spot x_l, and L_f(x_v) = exp(+2 pi i f |x_v - x_l|)
  undoes the laser-side leg (a per-voxel factor);
* m = 2 for confocal scans (x_l = x_s: the path doubles), and L_f = 1;
* P'_f(x_s) = P_f(x_s) * exp(+2 pi i f device_path(x_s)) undoes the device legs
  when the field's geometry says its time axis still contains them;
* the amplitude factor is 1/r_s (no obliquity factor), for both capture kinds.

The ``rsd`` imager evaluates the sum directly; the ``fft`` imager evaluates the
same sum as a convolution over the wall (the kernel depends on x_v - x_s only).
"""

from __future__ import annotations

import numpy as np

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import DataError
from nlosfw.transform.field import PhasorField
from nlosfw.transform.frequencies import uniform_step
from nlosfw.transform.temporal_dft import unit_phasor


def path_multiplier(geometry: CaptureGeometry) -> int:
    """m: 1 for a single laser spot, 2 for confocal scans (DataError otherwise)."""
    check_geometry(geometry)
    return 2 if geometry.kind is CaptureKind.CONFOCAL else 1


def check_geometry(geometry: CaptureGeometry) -> None:
    """DataError unless the field's geometry can be imaged."""
    if not isinstance(geometry, CaptureGeometry):
        raise DataError(f"field.geometry: expected a CaptureGeometry, got "
                        f"{type(geometry).__name__}")
    if geometry.kind is CaptureKind.EXHAUSTIVE:
        raise DataError("field.geometry: kind exhaustive cannot be imaged from one wall field; "
                        "valid: single_spot, confocal")
    if geometry.kind is CaptureKind.SINGLE_SPOT:
        lp = geometry.laser_point
        if lp is None or np.asarray(lp).shape != (3,) or not np.all(np.isfinite(lp)):
            raise DataError("field.geometry.laser_point: a single-spot field needs its laser spot "
                            "on the wall as 3 finite coordinates")


def wall_field(field: PhasorField, dtype: type = np.complex128) -> np.ndarray:
    """P'_f: the field's values (F, Y, X) with the device legs undone (a new array)."""
    values = np.array(field.values, dtype=dtype)
    geometry = field.geometry
    if geometry.t_accounts_first_and_last_bounces:
        legs = geometry.device_path(field.wall_xyz)                  # (Y, X)
        for i, f in enumerate(field.frequencies):
            values[i] *= unit_phasor(f * legs, dtype)
    return values


def laser_phase(frequencies: np.ndarray, voxels: np.ndarray, geometry: CaptureGeometry,
                dtype: type = np.complex128) -> np.ndarray | None:
    """L_f(x_v) = exp(+2 pi i f |x_v - x_l|), shape (F, *voxels.shape[:-1]); None if confocal."""
    if geometry.kind is CaptureKind.CONFOCAL:
        return None
    r_l = np.linalg.norm(np.asarray(voxels, float) - np.asarray(geometry.laser_point, float),
                         axis=-1)
    return phasor_series(frequencies, r_l, dtype)


def kernel(frequencies: np.ndarray, r: np.ndarray, multiplier: int,
           dtype: type = np.complex128, out: np.ndarray | None = None) -> np.ndarray:
    """exp(+2 pi i f m r) / r for every frequency, shape (F, *r.shape) (into ``out`` if given)."""
    r = np.asarray(r, dtype=float)
    return phasor_series(frequencies, multiplier * r, dtype, out, scale=1.0 / r)


def phasor_series(frequencies: np.ndarray, path: np.ndarray, dtype: type = np.complex128,
                  out: np.ndarray | None = None, scale: np.ndarray | None = None) -> np.ndarray:
    """scale * exp(+2 pi i f path) for every frequency, shape (F, *path.shape).

    For uniformly spaced frequencies each step multiplies by exp(2 pi i df path)
    in float64, recomputed exactly every 64 steps (error ~1e-14), instead of
    evaluating cos and sin for every frequency.
    """
    f = np.asarray(frequencies, dtype=float)
    path = np.asarray(path, dtype=float)
    if out is None:
        out = np.empty(f.shape + path.shape, dtype=dtype)
    step = uniform_step(f) if f.size > 2 else None
    if step is None:
        for i, fi in enumerate(f):
            out[i] = unit_phasor(fi * path, out.dtype)
            if scale is not None:
                out[i] *= scale
        return out
    advance = unit_phasor(step * path)
    current = None
    for i, fi in enumerate(f):
        if i % _REFRESH == 0:
            current = unit_phasor(fi * path)
            if scale is not None:
                current *= scale
        else:
            current *= advance
        out[i] = current
    return out


#: Steps of the frequency recurrence between exact evaluations.
_REFRESH = 64

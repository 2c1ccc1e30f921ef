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

from collections.abc import Iterator

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
    values: np.ndarray = np.array(field.values, dtype=dtype)
    geometry = field.geometry
    if geometry.t_accounts_first_and_last_bounces:
        legs = geometry.device_path(field.wall_xyz)                  # (Y, X)
        for i, f in enumerate(field.frequencies):
            values[i] *= unit_phasor(f * legs, dtype)
    return values


def laser_phase(frequencies: np.ndarray, voxels: np.ndarray, geometry: CaptureGeometry,
                dtype: type = np.complex128) -> np.ndarray | None:
    """L_f(x_v) = exp(+2 pi i f |x_v - x_l|), shape (F, *voxels.shape[:-1]); None if confocal."""
    r_l = laser_distances(voxels, geometry)
    return None if r_l is None else phasor_series(frequencies, r_l, dtype)


def laser_distances(voxels: np.ndarray, geometry: CaptureGeometry) -> np.ndarray | None:
    """|x_v - x_l| for every voxel, shape voxels.shape[:-1]; None if confocal."""
    if geometry.kind is CaptureKind.CONFOCAL:
        return None
    return np.linalg.norm(np.asarray(voxels, float) - np.asarray(geometry.laser_point, float),
                          axis=-1)


def kernel(frequencies: np.ndarray, r: np.ndarray, multiplier: int,
           dtype: type = np.complex128, out: np.ndarray | None = None) -> np.ndarray:
    """exp(+2 pi i f m r) / r for every frequency, shape (F, *r.shape) (into ``out`` if given)."""
    r = np.asarray(r, dtype=float)
    return phasor_series(frequencies, multiplier * r, dtype, out, scale=1.0 / r)


def kernel_blocks(frequencies: np.ndarray, r: np.ndarray, multiplier: int,
                  out: np.ndarray) -> Iterator[slice]:
    """Kernels exp(+2 pi i f m r) / r for blocks of ``out.shape[0]`` consecutive frequencies
    (see :func:`phasor_blocks`)."""
    r = np.asarray(r, dtype=float)
    return phasor_blocks(frequencies, multiplier * r, out, scale=1.0 / r)


def phasor_blocks(frequencies: np.ndarray, path: np.ndarray, out: np.ndarray,
                  scale: np.ndarray | None = None) -> Iterator[slice]:
    """scale * exp(+2 pi i f path) for blocks of ``out.shape[0]`` consecutive frequencies.

    Fills ``out[:k]`` (a block of k frequencies, ``out`` of shape (block, *path.shape),
    any complex dtype, possibly a strided view) and yields the block's slice of
    ``frequencies``; the next block overwrites it. For uniformly spaced frequencies (in
    the given order) a block's phasors are its first phasor (from :func:`phasor_steps`
    over the blocks' first frequencies, which sets the order of the blocks) times the
    fixed phasors exp(2 pi i j df path), j < block: one complex product per value instead
    of a cosine and a sine. Otherwise every phasor is evaluated exactly, block by block
    in order.
    """
    f = np.asarray(frequencies, dtype=float)
    path = np.asarray(path, dtype=float)
    size = out.shape[0]
    step = uniform_step(f) if f.size > 2 else None
    starts = range(0, f.size, size)
    if step is None:
        for start in starts:
            sel = slice(start, min(f.size, start + size))
            phasor_series(f[sel], path, out.dtype.type, out=out[:sel.stop - start], scale=scale)
            yield sel
        return
    within = unit_phasor(np.multiply.outer(step * np.arange(size), path), out.dtype.type)
    for b, first in phasor_steps(f[::size], path, scale=scale):    # each block's first
        start = b * size
        k = min(size, f.size - start)
        np.multiply(within[:k], first, out=out[:k], casting="same_kind")
        yield slice(start, start + k)


def phasor_series(frequencies: np.ndarray, path: np.ndarray, dtype: type = np.complex128,
                  out: np.ndarray | None = None, scale: np.ndarray | None = None) -> np.ndarray:
    """scale * exp(+2 pi i f path) for every frequency, shape (F, *path.shape).

    Stores every frequency's phasor; :func:`phasor_steps` yields them one at a time.
    """
    f = np.asarray(frequencies, dtype=float)
    if out is None:
        out = np.empty(f.shape + np.shape(path), dtype=dtype)
    for i, phasor in phasor_steps(f, path, out.dtype.type, scale):
        out[i] = phasor
    return out


def phasor_steps(frequencies: np.ndarray, path: np.ndarray, dtype: type = np.complex128,
                 scale: np.ndarray | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """(i, scale * exp(+2 pi i f_i path)) for every frequency, one frequency at a time.

    Memory stays at a few arrays of ``path``'s shape whatever the number of
    frequencies: the yielded array is reused for the next frequency (copy it to
    keep it). When the frequencies, in ascending order, are uniformly spaced by
    df, they are visited in that order and each step multiplies by
    exp(2 pi i df path) in complex128, recomputed exactly every 256 steps (error
    ~1e-13), instead of evaluating cos and sin for every frequency; otherwise each
    phasor is evaluated exactly in ``dtype``, in the given order.
    """
    f = np.asarray(frequencies, dtype=float)
    path = np.asarray(path, dtype=float)
    order = np.argsort(f, kind="stable")
    step = uniform_step(f[order]) if f.size > 2 else None
    if step is None:
        for i, fi in enumerate(f):
            phasor = unit_phasor(fi * path, dtype)
            if scale is not None:
                phasor *= scale
            yield i, phasor
        return
    advance = unit_phasor(step * path)
    current = np.empty(path.shape, dtype=np.complex128)
    for j, i in enumerate(order):
        if j % _REFRESH == 0:
            current[...] = unit_phasor(f[i] * path)
            if scale is not None:
                current *= scale
        else:
            current *= advance
        yield int(i), current


#: Steps of the frequency recurrence between exact evaluations (float64: the
#: recurrence drifts by ~1e-16 per step).
_REFRESH = 256

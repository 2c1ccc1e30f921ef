"""A reference light-cone transform, written from the paper's equations (O'Toole, Lindell and
Wetzstein, "Confocal non-line-of-sight imaging based on the light-cone transform", Nature 555,
2018), independently of ``nlosfw/image/lct.py``; the tests compare the ``lct`` imager with it.

The paper's model of a confocal capture with a 1/r^n falloff, d = t/2:

    tau(x', y', d) = integral rho(x, y, z) / r^n delta(r - d),  r^2 = (x-x')^2 + (y-y')^2 + z^2

With v = d^2 and u = z^2 it becomes a 3-D convolution (their eq. 4-5):

    R_t{tau}(x', y', v) = d^(n-1) tau(d)  =  (h * R_z{rho})(x', y', v),
    h(x, y, v) = delta(x^2 + y^2 - v),     R_z{rho}(u) = rho(sqrt u) / sqrt u

inverted by a Wiener filter  conj(H) / (|H|^2 + 1/snr)  (their eq. 6, h of unit energy as in
their code), then rho(z) = z R_z(z^2).

Two functions:

* :func:`reference_lct` - the same discretisation as the imager's documented one, applied to
  the complex transient that imager sees (the full-band analytic signal of the histograms),
  so that the two agree to rounding: v sampled at j dv (each sample the average of the
  falloff-compensated transient, linearly interpolated in t, over its bin), the cone split
  linearly between its two nearest v samples, both zero-padded (next fast FFT length of twice
  the size) for a linear convolution, depths read by linear interpolation in v = z^2.
* :func:`authors_lct` - the authors' published procedure on the real histograms (their
  ``cnlos_reconstruction.m``: t^n scaling on a [0, 1] time grid, their nearest-sample
  resampling operator and its transpose, their cone kernel on a grid of slope
  width/range, Wiener filter, ``max(real(vol), 0)``, their depth window ``z_offset`` to
  ``z_offset + 2 width / dz``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft


def analytic_transient(histograms: np.ndarray, bin_width: float, times: np.ndarray
                       ) -> np.ndarray:
    """h(t) = sum over the positive DFT bins k = 1 .. T/2 of the histogram's spectrum, i.e.
    sum_k sum_i H_i dt exp(2 pi i f_k (t - t_i)), t_i = (i + 1/2) dt, f_k = k / (T dt), at
    ``times`` (multiples of dt/2, path from the wall); (len(times), Y, X) complex."""
    n = histograms.shape[0]
    # the histogram on a grid of dt/2: bin i at sample 2 i + 1, zeros between
    fine = np.zeros((2 * n,) + histograms.shape[1:], dtype=np.float64)
    fine[1::2] = histograms
    spectrum = np.fft.fft(fine, axis=0)
    keep = np.zeros(2 * n, dtype=bool)
    keep[1:n // 2 + 1] = True
    spectrum[~keep] = 0
    periodic = np.fft.ifft(spectrum, axis=0) * (2 * n) * bin_width
    index = np.rint(np.asarray(times) / (bin_width / 2)).astype(np.int64)
    return periodic[index % (2 * n)]


@dataclass(frozen=True)
class Settings:
    """The imager's parameters: falloff 1/r^n, Wiener snr, most v samples, time samples per
    shortest wavelength."""

    falloff_power: int
    snr: float
    max_bins: int = 2048
    samples_per_wavelength: float = 4.0


@dataclass(frozen=True)
class AuthorsSettings:
    """The authors' per-scene settings: diffuse (t^4) or not (t^2), snr, bins zeroed, first
    bin of the depth window, 2^downsample bins summed."""

    diffuse: bool
    snr: float
    z_trim: int = 600
    z_offset: int = 0
    downsample: int = 0


def reference_lct(histograms: np.ndarray, bin_width: float, spacing: tuple[float, float],
                  depths: np.ndarray, settings: Settings) -> np.ndarray:
    """|rho|^2 on (len(depths), Y, X) from histograms (T, Y, X) with t_start = 0, imaged from
    every positive DFT bin (see the module docstring)."""
    falloff_power, snr, max_bins = settings.falloff_power, settings.snr, settings.max_bins
    samples_per_wavelength = settings.samples_per_wavelength
    n_bins, ny, nx = histograms.shape
    depths = np.asarray(depths, dtype=float)
    dt = 1.0 / (samples_per_wavelength * (n_bins // 2) / (n_bins * bin_width))
    period = n_bins * bin_width
    start = max(0.0, 2 * depths.min() - period / 4)
    # the v grid: depth step at the nearest depth at most dt/2, to past the farthest path
    dz = dt / 2
    far = math.sqrt((depths.max() + 4 * dz) ** 2 + ((ny - 1) * spacing[0]) ** 2
                    + ((nx - 1) * spacing[1]) ** 2)
    m = math.ceil(far ** 2 / (2 * max(depths.min(), dz) * dz))
    m = min(max(m, math.ceil(far / dz), 16), max_bins)
    dv = far ** 2 / m
    shape = tuple(scipy.fft.next_fast_len(2 * s) if s > 1 else 1 for s in (m, ny, nx))

    # R_t: d^(n-1) h(t) on the t grid, averaged over each v bin
    n_t = math.ceil(2 * math.sqrt(m * dv) / dt) + 2
    times = np.arange(n_t) * dt
    h = analytic_transient(histograms, bin_width, times)
    h[(times < start) | (times >= start + period)] = 0
    h *= ((times / 2) ** (falloff_power - 1))[:, None, None]
    sub = math.ceil(2 * math.sqrt(dv / 2) / dt) + 1
    r_t = np.zeros((m, ny, nx), dtype=complex)
    for j in range(m):
        v = np.maximum((j - 0.5 + (np.arange(sub) + 0.5) / sub) * dv, 0.0)
        pos = 2 * np.sqrt(v) / dt
        below = np.floor(pos).astype(int)
        for b, w in zip(below, pos - below, strict=True):
            if b < n_t:
                r_t[j] += (1 - w) / sub * h[b]
            if b + 1 < n_t:
                r_t[j] += w / sub * h[b + 1]

    # the light cone x^2 + y^2 = v on the padded grid, unit energy
    cone = np.zeros(shape)
    for iy in range(-(ny - 1), ny):
        for ix in range(-(nx - 1), nx):
            w = ((iy * spacing[0]) ** 2 + (ix * spacing[1]) ** 2) / dv
            k = math.floor(w)
            for kk, weight in ((k, 1 - (w - k)), (k + 1, w - k)):
                if kk < m:
                    cone[kk, iy % shape[1], ix % shape[2]] += weight
    cone /= np.linalg.norm(cone)
    kernel = np.fft.fftn(cone)
    wiener = np.conj(kernel) / (np.abs(kernel) ** 2 + 1 / snr)
    r_z = np.fft.ifftn(np.fft.fftn(r_t, s=shape, axes=(0, 1, 2)) * wiener)[:m, :ny, :nx]

    # rho(z) = z R_z(z^2), R_z linearly interpolated in v
    pos = depths ** 2 / dv
    out = np.zeros((depths.size, ny, nx), dtype=complex)
    for i, p in enumerate(pos):
        k = math.floor(p)
        for kk, weight in ((k, 1 - (p - k)), (k + 1, p - k)):
            if 0 <= kk < m:
                out[i] += weight * r_z[kk]
    out *= depths[:, None, None]
    return np.abs(out) ** 2


def authors_lct(rect_data: np.ndarray, width: float, bin_seconds: float,
                settings: AuthorsSettings) -> tuple[np.ndarray, np.ndarray]:
    """The authors' reconstruction of ``rect_data`` (N, N, T) as in their MATLAB code:
    (volume max(real, 0) over their depth window, shape (Z, N, N) with rows along y and
    columns along x, both increasing (nlosfw's canonical wall grid: the file's axes reversed,
    see nlosfw.capture.lct); depths of its planes, m). ``downsample`` k sums 2^k bins
    as their K option does (z_trim and z_offset halved with it)."""
    c = 3e8
    diffuse, snr, z_trim = settings.diffuse, settings.snr, settings.z_trim
    z_offset, downsample = settings.z_offset, settings.downsample
    data = np.asarray(rect_data, dtype=np.float64)
    for _ in range(downsample):
        data = data[:, :, 0::2] + data[:, :, 1::2]
        bin_seconds *= 2
        z_trim = round(z_trim / 2)
        z_offset = round(z_offset / 2)
    n, _, m = data.shape
    span = m * c * bin_seconds                                # "range"
    data[:, :, :z_trim] = 0
    data = np.transpose(data, (2, 1, 0))                      # permute [3 2 1]: (M, N, N)
    grid_z = np.linspace(0, 1, m)[:, None, None]
    data = data * grid_z ** (4 if diffuse else 2)
    # resampling operator: row r (of M) averages 1/sqrt(x) at column ceil(sqrt(x)) - 1 over
    # x = r M + 1 .. (r + 1) M (their M^2 rows halved log2(M) times)
    x = np.arange(1, m * m + 1, dtype=np.float64)
    rows = (x - 1).astype(np.int64) // m
    cols = np.ceil(np.sqrt(x)).astype(np.int64) - 1
    mtx = np.zeros((m, m))
    np.add.at(mtx, (rows, cols), 1.0 / (m * np.sqrt(x)))
    tdata = np.zeros((2 * m, 2 * n, 2 * n))
    tdata[:m, :n, :n] = (mtx @ data.reshape(m, -1)).reshape(m, n, n)
    psf = _authors_psf(n, m, width / span)
    fpsf = scipy.fft.fftn(psf, workers=1)
    invpsf = np.conj(fpsf) / (np.abs(fpsf) ** 2 + 1 / snr)
    tvol = scipy.fft.ifftn(scipy.fft.fftn(tdata, workers=1) * invpsf, workers=1)[:m, :n, :n]
    vol = (mtx.T @ tvol.reshape(m, -1)).reshape(m, n, n)
    vol = np.maximum(vol.real, 0)
    tic_z = np.linspace(0, span / 2, m)
    ind = round(m * 2 * width / (span / 2))
    window = slice(z_offset, min(ind + z_offset, m))
    return vol[window][:, ::-1, ::-1], tic_z[window]


#: The authors' scene settings (cnlos_reconstruction.m and the issue's reading of it).
AUTHORS_SCENES: dict[str, AuthorsSettings] = {
    "data_resolution_chart_40cm": AuthorsSettings(diffuse=False, snr=0.8, z_offset=350),
    "data_dot_chart_40cm": AuthorsSettings(diffuse=False, snr=0.8, z_offset=350),
    "data_diffuse_s": AuthorsSettings(diffuse=True, snr=0.08, z_offset=100),
}


def _authors_psf(n: int, m: int, slope: float) -> np.ndarray:
    """Their definePsf: per lateral cell the z sample nearest the cone, normalised."""
    x = np.linspace(-1, 1, 2 * n)
    z = np.linspace(0, 2, 2 * m)
    gz, gy, gx = np.meshgrid(z, x, x, indexing="ij")
    dist = np.abs((4 * slope) ** 2 * (gx ** 2 + gy ** 2) - gz)
    psf = (dist == dist.min(axis=0, keepdims=True)).astype(np.float64)
    psf /= psf[:, n - 1, n - 1].sum()      # MATLAB psf(:, U, U), 1-based
    psf /= np.linalg.norm(psf)
    return np.roll(psf, (n, n), axis=(1, 2))

"""The temporal Fourier transform of a histogram at chosen frequencies, streamed.

    P_f(s) = sum_i H[i, s] * exp(-2 pi i f t_i) * delta_t,   t_i = t_start + (i + 1/2) delta_t

(``t_i`` are bin centres; f in cycles per metre of path). Two exact ways:

* ``direct``: a matrix product with the cos/sin table of the frequencies,
  streamed over the time axis in chunks (BLAS ``dgemm`` accumulating in place),
  so memory stays at about twice the output whatever the number of bins;
* ``fft``: when every frequency is bin k of a length-N DFT (f = k / (N delta_t),
  N >= number of bins), a zero-padded real FFT per block of sensors, then the
  bin-centre phase exp(-2 pi i f (t_start + delta_t/2)).

Phases are reduced modulo one cycle in float64 before cos/sin, so the result
matches a brute-force float64 DFT to about 1e-12 relative.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
from scipy.linalg import blas

from nlosfw.common.config import Choice
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.transform.frequencies import dft_length


class DftMethod(Choice):
    """How the temporal DFT is evaluated: ``fft`` needs exact DFT bins, ``direct`` is a
    streamed matrix product, ``auto`` picks the cheaper one."""

    auto = "auto"
    direct = "direct"
    fft = "fft"


#: Working memory of a chunk, at least this many bytes even for tiny outputs.
_MIN_CHUNK_BYTES = 8 << 20


def unit_phasor(cycles: np.ndarray, dtype: type = np.complex128) -> np.ndarray:
    """exp(2 pi i * cycles), with the argument reduced modulo 1 in float64 first.

    ``dtype`` complex64 evaluates cos/sin in float32 after the float64 reduction.
    """
    cycles = np.asarray(cycles, dtype=np.float64)
    frac = cycles - np.rint(cycles)                                  # in [-1/2, 1/2]
    frac *= 2.0 * np.pi
    real = np.float32 if np.dtype(dtype) == np.complex64 else np.float64
    angle = frac.astype(real, copy=False)
    out = np.empty(angle.shape, dtype=dtype)
    np.cos(angle, out=out.real)
    np.sin(angle, out=out.imag)
    return out


def choose_method(frequencies: np.ndarray, delta_t: float, n_bins: int,
                  method: str = "auto") -> tuple[str, int | None]:
    """('direct' | 'fft', DFT length or None) for these frequencies.

    ``auto`` takes the FFT when the frequencies are exact DFT bins and the FFT
    is estimated to be cheaper than the matrix product.
    """
    n = dft_length(frequencies, delta_t, n_bins)
    if method == "direct":
        return "direct", None
    if method == "fft":
        if n is None:
            raise ConfigError("method", "fft needs frequencies that are exact bins k/(N*delta_t) "
                                        f"of a DFT of length N >= {n_bins}; use auto or direct")
        return "fft", n
    if n is None:
        return "direct", None
    direct_cost = float(len(frequencies)) * n_bins
    fft_cost = 8.0 * n * np.log2(max(n, 2))   # measured: FFTs run well below BLAS speed
    return ("fft", n) if fft_cost < direct_cost else ("direct", None)


def temporal_dft(H: np.ndarray, t_start: float, delta_t: float, frequencies: np.ndarray,
                 method: str = "auto", max_chunk_bytes: int | None = None
                 ) -> tuple[np.ndarray, str]:
    """P[f, s] for a histogram ``H`` of shape (T, S); returns (complex128 (F, S), method used).

    ``max_chunk_bytes`` bounds the working memory of one chunk (default: a
    quarter of the output, at least 8 MiB), so the peak stays near twice the
    output (accumulator plus result) for large outputs.
    """
    H = np.asarray(H)
    if H.ndim != 2:
        raise DataError(f"H: must be (time, sensors) for the temporal DFT, got shape {H.shape}")
    f = np.asarray(frequencies, dtype=np.float64)
    n_bins, n_sensors = H.shape
    out_bytes = 16 * f.size * n_sensors
    budget = max(_MIN_CHUNK_BYTES, out_bytes // 4 if max_chunk_bytes is None else max_chunk_bytes)
    used, n_fft = choose_method(f, delta_t, n_bins, method)
    if used == "fft":
        assert n_fft is not None
        return _by_fft(H, t_start, delta_t, f, n_fft, budget), used
    return _direct(H, t_start, delta_t, f, budget), used


def _direct(H: np.ndarray, t_start: float, delta_t: float, f: np.ndarray,
            budget: int) -> np.ndarray:
    n_bins, n_sensors = H.shape
    n_f = f.size
    chunk = int(max(1, min(n_bins, budget // (8 * (2 * n_f + n_sensors)))))
    # acc[:F] accumulates the real parts, acc[F:] the imaginary parts (Fortran order so
    # that dgemm updates it in place: acc = table^T-chunk @ H-chunk + acc).
    acc = np.zeros((2 * n_f, n_sensors), dtype=np.float64, order="F")
    for start in range(0, n_bins, chunk):
        stop = min(n_bins, start + chunk)
        t = t_start + (np.arange(start, stop) + 0.5) * delta_t
        cycles = (t[:, None] * f[None, :]) % 1.0                      # (B, F)
        table = np.empty((stop - start, 2 * n_f), dtype=np.float64)   # C order (B, 2F)
        np.cos(2.0 * np.pi * cycles, out=table[:, :n_f])
        np.sin(2.0 * np.pi * cycles, out=table[:, n_f:])
        table[:, n_f:] *= -1.0
        block = np.ascontiguousarray(H[start:stop], dtype=np.float64)  # (B, S)
        # table.T is (2F, B) and block.T is (S, B), both Fortran-ordered views: no copies.
        acc = blas.dgemm(delta_t, table.T, block.T, beta=1.0, c=acc, trans_a=0, trans_b=1,
                         overwrite_c=1)
    out = np.empty((n_f, n_sensors), dtype=np.complex128)
    out.real = acc[:n_f]
    out.imag = acc[n_f:]
    return out


def _by_fft(H: np.ndarray, t_start: float, delta_t: float, f: np.ndarray, n_fft: int,
            budget: int) -> np.ndarray:
    n_bins, n_sensors = H.shape
    k = np.round(f * n_fft * delta_t).astype(np.int64)
    shift = delta_t * unit_phasor(-f * (t_start + 0.5 * delta_t))     # bin-centre phase
    out = np.empty((f.size, n_sensors), dtype=np.complex128)
    per_sensor = 16 * (n_fft // 2 + 1) + 8 * n_fft
    chunk = int(max(1, min(n_sensors, budget // per_sensor)))
    for start in range(0, n_sensors, chunk):
        stop = min(n_sensors, start + chunk)
        block = np.asarray(H[:, start:stop], dtype=np.float64)
        spec = scipy.fft.rfft(block, n=n_fft, axis=0, workers=-1)
        out[:, start:stop] = spec[k] * shift[:, None]
    return out

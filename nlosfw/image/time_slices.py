"""A plane's coherent sum over many frequencies from a few time slices of its kernel.

For uniformly spaced frequencies f_j = f_c + j' df (j' = j - c, f_c the middle one) the
kernel of :mod:`nlosfw.image.rsd_kernel` at lattice offset u is
h_j(u) = g(u) exp(2 pi i j' x(u)), with g the kernel at f_c and x(u) = df m r(u). A
coherent confocal image sums over frequencies before its inverse FFT,

    Q(k) = sum_j S_j(k) H_j(k) = sum_u C(k, u) g(u) s_k(x(u)),
    s_k(x) = sum_j' S_j(k) exp(2 pi i j' x),

(S_j the field's spectrum times its coefficient, H_j = C h_j the kernel's transform: a
type-I DCT or an FFT). s_k is a trigonometric polynomial: the type-2 non-uniform FFT
interpolates it from N = ``OVERSAMPLING`` x F samples in x with a window phi of ``WIDTH``
samples (the "exponential of semicircle" window, Barnett, Magland and af Klinteberg 2019),
s_k(x) ~ sum_t phi(N x - t) V_t(k), where

    V_t(k) = sum_j' S_j(k) / phi_hat(j' / N) exp(2 pi i j' t / N)

is one length-N FFT over the frequencies shared by every plane (:func:`time_spectra`).
So Q(k) ~ sum_t V_t(k) G_t(k) with G_t the transform of the kernel's time slice
g(u) phi(N x(u) - t) (:meth:`TimeSlices.kernel_blocks`): one transform and one product
per slice instead of per frequency. A plane has the slices t within WIDTH / 2 of N x(u),
about OVERSAMPLING x F x df m (r_max - r_min) + WIDTH of them (r over the plane's kernel
samples): for a 2 m wall and planes from 0.6 to 1.6 m, 37 to 47 slices for 151
frequencies. Every frequency's phasor is interpolated to 1.4e-7, complex64's rounding.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.fft

from nlosfw.transform.frequencies import uniform_step
from nlosfw.transform.temporal_dft import unit_phasor

#: Samples in x per frequency (sigma of the non-uniform FFT).
OVERSAMPLING = 1.25
#: Samples of the window (its width in slices).
WIDTH = 13
#: Shape parameter of the window: beta = 0.97 pi (1 - 1 / (2 sigma)) W (Barnett et al.).
BETA = 0.97 * np.pi * (1 - 1 / (2 * OVERSAMPLING)) * WIDTH
#: Gauss-Legendre nodes of the window's Fourier transform.
_QUADRATURE = 64


def window(y: np.ndarray) -> np.ndarray:
    """phi(y) = exp(beta (sqrt(1 - (2 y / W)^2) - 1)) for |y| < W / 2, else 0 (y in slices)."""
    a = 2.0 * np.asarray(y, dtype=float) / WIDTH
    a *= a
    np.subtract(1.0, a, out=a)
    inside = a > 0
    np.sqrt(a, out=a, where=inside)
    a -= 1.0
    a *= BETA
    return np.exp(a, out=a, where=inside) * inside


def window_spectrum(xi: np.ndarray) -> np.ndarray:
    """phi_hat(xi) = integral of phi(y) exp(-2 pi i xi y) dy (real: phi is even)."""
    nodes, weights = np.polynomial.legendre.leggauss(_QUADRATURE)
    y = nodes * WIDTH / 2
    return np.asarray((weights * WIDTH / 2 * window(y)) @ np.cos(
        2 * np.pi * np.outer(y, np.asarray(xi, dtype=float))))


@dataclass(frozen=True)
class TimeSlices:
    """The slice grid of uniformly spaced frequencies (see the module docstring)."""

    frequencies: np.ndarray
    """f_j in the field's order."""
    multiplier: int
    """m: 1 single spot, 2 confocal."""
    n: int
    """N: slices per period of x (a fast FFT length >= OVERSAMPLING x F)."""
    origin: int
    """The first stored slice: V's row i holds slice origin + i (mod N)."""

    @property
    def centre(self) -> int:
        """c: the index of the middle frequency f_c."""
        return (self.frequencies.size - 1) // 2

    @property
    def offsets(self) -> np.ndarray:
        """j' = j - c."""
        return np.arange(self.frequencies.size) - self.centre

    @property
    def step(self) -> float:
        """df (negative for descending frequencies)."""
        return float(self.frequencies[1] - self.frequencies[0])

    def position(self, r: np.ndarray) -> np.ndarray:
        """N x(u) = N df m r: where a kernel sample at distance r sits, in slices."""
        return self.n * self.step * self.multiplier * np.asarray(r, dtype=float)

    def span(self, r_min: float, r_max: float) -> tuple[int, int]:
        """(first, last) slice of a plane whose kernel distances lie in [r_min, r_max]."""
        ends = self.position(np.array([r_min, r_max]))
        return int(np.ceil(ends.min() - WIDTH / 2)), int(np.ceil(ends.max() - WIDTH / 2)) + \
            WIDTH - 1

    def weights(self) -> np.ndarray:
        """Per frequency: exp(2 pi i j' origin / N) / phi_hat(j' / N), the factor of S_j in
        V's rows (complex128)."""
        j = self.offsets
        return unit_phasor(j * self.origin / self.n) / window_spectrum(j / self.n)

    def rows(self, first: int, stop: int) -> slice | np.ndarray:
        """V's rows of slices first ... stop - 1: a slice, or indices where they wrap."""
        start = first - self.origin
        if start >= 0 and stop - self.origin <= self.n:
            return slice(start, stop - self.origin)
        return np.arange(start, stop - self.origin) % self.n

    def kernel_blocks(self, r: np.ndarray, out: np.ndarray) -> Iterator[slice | np.ndarray]:
        """The kernel's time slices g(u) phi(N x(u) - t), t over the plane's slices, for
        blocks of ``out.shape[0]`` consecutive slices.

        Fills ``out[:k]`` (``out`` of shape (block, *r.shape), complex, possibly a strided
        view; zero where a slice has no sample) and yields V's rows of the block's slices
        (:meth:`rows`); the next block overwrites it. Each sample has ``WIDTH`` slices: they
        are written by index into the memory ``out`` spans, not by a dense evaluation.
        """
        r = np.asarray(r, dtype=float)
        g = unit_phasor(self.frequencies[self.centre] * self.multiplier * r, out.dtype.type)
        g /= r.astype(g.real.dtype)
        x = self.position(r).reshape(-1)
        start = np.ceil(x - WIDTH / 2).astype(np.intp)
        first, last = int(start.min()), int(start.max()) + WIDTH - 1
        taps = np.arange(WIDTH)[:, None]                                  # (W, 1)
        values = window((x - start)[None, :] - taps)                      # (W, P)
        values = np.multiply(values, g.reshape(1, -1), dtype=out.dtype).reshape(-1)
        # where each tap goes: its slice's step and the sample's place in a slice, in
        # items of the memory ``out`` spans
        steps = [stride // out.itemsize for stride in out.strides]
        cells = sum(i * step for i, step in zip(np.indices(r.shape), steps[1:], strict=True))
        slices = (start - first)[None, :] + taps                          # (W, P)
        places = (slices * steps[0] + cells.reshape(1, -1)).reshape(-1)
        slices = slices.reshape(-1)
        size = out.shape[0]
        for lo in range(first, last + 1, size):
            k = min(size, last + 1 - lo)
            block = out[:k]
            block[...] = 0
            memory = np.lib.stride_tricks.as_strided(
                block, shape=(sum((n - 1) * st for n, st in zip(block.shape, steps,
                                                                 strict=True)) + 1,),
                strides=(block.itemsize,))
            if k == last + 1 - first:                                  # the whole plane
                memory[places] = values
            else:
                mask = (slices >= lo - first) & (slices < lo - first + k)
                memory[places[mask] - (lo - first) * steps[0]] = values[mask]
            yield self.rows(lo, lo + k)


def time_slices(frequencies: np.ndarray, multiplier: int, r_min: float,
                r_max: float) -> TimeSlices | None:
    """The slice grid of ``frequencies`` (None unless more than two and uniformly spaced),
    its stored rows starting at the first slice of the kernel distances [r_min, r_max] of
    every plane."""
    f = np.asarray(frequencies, dtype=float)
    if f.size < 3 or uniform_step(f) is None:
        return None
    n = scipy.fft.next_fast_len(int(np.ceil(OVERSAMPLING * f.size)))
    first, _ = TimeSlices(f, multiplier, n, 0).span(r_min, r_max)
    return TimeSlices(f, multiplier, n, first)


def time_spectra(grid: TimeSlices, spectra: Callable[[slice], np.ndarray], axis: int,
                 block: int = 16, workers: int | None = None) -> np.ndarray:
    """V: the rows (N along ``axis``) of spectra S_j given ``block`` frequencies at a time
    (``spectra(frequencies)``: F_block along ``axis``), each times
    :meth:`TimeSlices.weights` (see the module docstring); their dtype. Holds V and one
    block of S_j at a time."""
    factor = grid.weights()
    out: np.ndarray | None = None
    for start in range(0, grid.frequencies.size, block):
        sel = slice(start, min(grid.frequencies.size, start + block))
        part = spectra(sel)
        if out is None:
            shape = list(part.shape)
            shape[axis] = grid.n
            out = np.zeros(shape, dtype=part.dtype)
        index: list[slice | np.ndarray] = [slice(None)] * part.ndim
        index[axis] = grid.offsets[sel] % grid.n
        out[tuple(index)] = part * factor[sel].astype(part.dtype).reshape(
            [-1 if i == axis else 1 for i in range(part.ndim)])
    if out is None:
        raise ValueError("time_spectra: no frequencies")
    return scipy.fft.ifft(out, axis=axis, norm="forward", overwrite_x=True, workers=workers)

"""The ``wavelet`` phasor transform: Liu's Gaussian virtual illumination, spectrally.

The virtual illumination pulse is

    K(t) = exp(-t^2 / (2 sigma^2)) * exp(2 pi i t / lambda_c),   sigma = n_cycles * lambda_c / 6

(t in metres of path; the ±3 sigma window holds ``n_cycles`` periods). Its
spectrum (forward transform ∫ K(t) exp(-2 pi i f t) dt) is the Gaussian

    K^(f) = sqrt(2 pi) sigma exp(-2 pi^2 sigma^2 (f - f_c)^2),   f_c = 1/lambda_c,

of width sigma_f = 1 / (2 pi sigma). The transform keeps the frequency bins
f_k = k * df within f_c ± 3 sigma_f and returns the plain temporal Fourier
transform P_f (same sign convention as ``fft``: P_f = sum_t H exp(-2 pi i f t_c)
delta_t) with the weights w_f = df * K^(f) in ``PhasorField.weights``. Then
sum_f w_f exp(2 pi i f t) ≈ K(t) for |t| < 1/(2 df), and an imager forms the
t = 0 image of the filtered wave as |sum_f w_f U_f(x_v)|^2, U_f the field
propagated to voxel x_v (a time-resolved image multiplies w_f by exp(2 pi i f t)).

The default frequency step is df = 1 / (N delta_t) with N >= n_bins + 6 sigma /
delta_t (the capture window plus the pulse length, so the image at any voxel
in the window does not wrap around in time); the bins are then exact DFT bins.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.fft

from nlosfw.capture.data import Capture
from nlosfw.common.config import require
from nlosfw.common.errors import ConfigError
from nlosfw.transform.common import FieldOptions, check_capture, transform_capture
from nlosfw.transform.field import Band, PhasorField
from nlosfw.transform.frequencies import (
    band_info,
    path_multiplier,
    validate_frequencies,
    wall_spacing,
)
from nlosfw.transform.interface import PhasorTransform, PhasorTransformConfig
from nlosfw.transform.temporal_dft import DftMethod

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WaveletTransformConfig(PhasorTransformConfig):
    """Options of the ``wavelet`` transform (Liu's virtual illumination)."""

    wavelength: float | None = None
    """[m] Central wavelength lambda_c (of path); default ``wavelength_factor`` x the grid
    spacing, doubled for confocal captures (their path doubles)."""
    wavelength_factor: float = 4.0
    """lambda_c as a multiple of the wall grid spacing Δ when ``wavelength`` is not given
    (times 2 for confocal captures: the same 4Δ wavelength on the wall)."""
    n_cycles: float = 5.0
    """Periods of the carrier within the pulse's ±3 sigma: sigma = n_cycles * lambda_c / 6."""
    sigma_range: float = 3.0
    """Keep the bins within f_c ± sigma_range * sigma_f."""
    frequency_step: float | None = None
    """[1/m] Spacing df of the kept bins; default 1/(N delta_t) with
    N >= n_bins + 6 sigma / delta_t."""
    grid_spacing: float | None = None
    """[m] Wall spacing Δ for ``wavelength_factor`` and the aliasing warning; default the
    capture's."""
    remove_device_legs: bool = True
    """Take the device-to-wall legs out of the phase when the capture's time axis has them."""
    method: DftMethod = DftMethod.auto
    """How the transform is evaluated (see the ``fft`` transform)."""

    def __post_init__(self) -> None:
        for name in ("wavelength", "frequency_step", "grid_spacing"):
            value = getattr(self, name)
            require(value is None or (math.isfinite(value) and value > 0), name,
                    f"must be a finite number > 0, got {value}")
        for name in ("wavelength_factor", "n_cycles", "sigma_range"):
            value = getattr(self, name)
            require(math.isfinite(value) and value > 0, name,
                    f"must be a finite number > 0, got {value}")


@dataclass(frozen=True)
class GaussianWavelet:
    """The virtual illumination K(t) = exp(-t^2/(2 sigma^2)) exp(2 pi i t / wavelength)."""

    wavelength: float
    sigma: float

    @property
    def centre_frequency(self) -> float:
        return 1.0 / self.wavelength

    @property
    def sigma_f(self) -> float:
        """Standard deviation of the spectrum (cycles per metre)."""
        return 1.0 / (2.0 * np.pi * self.sigma)

    def kernel(self, t: np.ndarray) -> np.ndarray:
        """K(t), complex."""
        t = np.asarray(t, dtype=float)
        return np.exp(-(t**2) / (2 * self.sigma**2)) * np.exp(2j * np.pi * t / self.wavelength)

    def spectrum(self, f: np.ndarray) -> np.ndarray:
        """Its forward Fourier transform ∫ K(t) exp(-2 pi i f t) dt (real, as a complex array)."""
        f = np.asarray(f, dtype=float)
        amp = np.sqrt(2 * np.pi) * self.sigma
        return (amp * np.exp(-2 * np.pi**2 * self.sigma**2 * (f - self.centre_frequency) ** 2)
                ).astype(np.complex128)


class WaveletTransform(PhasorTransform[WaveletTransformConfig]):
    """Spectral bins of Liu's Gaussian virtual illumination with their weights.

    See the module docstring for the kernel, the weights and the sign convention.
    """

    config_class = WaveletTransformConfig

    def wavelet_for(self, capture: Capture) -> tuple[GaussianWavelet, float | None]:
        """(the wavelet, the wall spacing used or None) for ``capture``."""
        cfg = self.config
        spacing = wall_spacing(cfg.grid_spacing, capture, required=cfg.wavelength is None)
        wavelength = cfg.wavelength
        if wavelength is None:
            assert spacing is not None  # wall_spacing required it
            wavelength = cfg.wavelength_factor * spacing * path_multiplier(capture.kind)
        return GaussianWavelet(wavelength, cfg.n_cycles * wavelength / 6.0), spacing

    def planned_frequencies(self, capture: Capture) -> np.ndarray | None:
        """The kept bins (:meth:`frequencies_for`)."""
        return self.frequencies_for(capture)[0]

    def frequencies_for(self, capture: Capture) -> tuple[np.ndarray, np.ndarray, dict[str, object]]:
        """(frequencies, weights, description) of the kept bins for ``capture``."""
        cfg = self.config
        wavelet, spacing = self.wavelet_for(capture)
        df = cfg.frequency_step
        n_fft = None
        if df is None:
            n_min = capture.n_bins + math.ceil(6.0 * wavelet.sigma / capture.delta_t)
            n_fft = scipy.fft.next_fast_len(n_min, real=True)
            df = 1.0 / (n_fft * capture.delta_t)
        half = cfg.sigma_range * wavelet.sigma_f
        fc = wavelet.centre_frequency
        k = np.arange(math.floor((fc - half) / df), math.ceil((fc + half) / df) + 1)
        f = k * df
        in_band = np.abs(f - fc) <= half * (1 + 1e-12)
        if np.any(in_band & (f <= 0)):
            log.warning("transform: the wavelet's band reaches f <= 0 (n_cycles = %g is too "
                        "few); bins at f <= 0 dropped", cfg.n_cycles)
        f = f[in_band & (f > 0)]
        if f.size == 0:
            raise ConfigError("transform.frequency_step",
                              f"no bin k*df (df = {df:.6g}) lies in the band {fc:.6g} ± "
                              f"{half:.6g} cycles/m; use a smaller frequency_step")
        option = "transform.wavelength"
        f = validate_frequencies(f, capture.delta_t, spacing, option, capture.kind, warn=False)
        weights = df * wavelet.spectrum(f)
        info = {
            "wavelength": float(wavelet.wavelength),
            "sigma": float(wavelet.sigma),
            "n_cycles": float(cfg.n_cycles),
            "centre_frequency": float(fc),
            "sigma_f": float(wavelet.sigma_f),
            "sigma_range": float(cfg.sigma_range),
            "frequency_step": float(df),
            "dft_length": n_fft,
            "grid_spacing": None if spacing is None else float(spacing),
            "kernel": "exp(-t^2/(2 sigma^2)) exp(2 pi i t / wavelength)",
        }
        info["band"] = band_info(f, spacing, capture.kind, option)
        return f, weights, info

    def transform(self, capture: Capture) -> PhasorField:
        """The phasor field at the wavelet's bins, with its spectral weights."""
        check_capture(capture, "wavelet")
        freqs, weights, info = self.frequencies_for(capture)
        band = info.pop("band")
        return transform_capture(capture, freqs, FieldOptions(
            transform="wavelet", method=self.config.method,
            remove_device_legs=self.config.remove_device_legs, weights=weights,
            metadata={"wavelet": info}, band=band if isinstance(band, Band) else None))

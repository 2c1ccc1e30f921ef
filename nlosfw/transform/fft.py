"""The ``fft`` phasor transform: the temporal Fourier transform at any frequencies.

Sign convention (used by every nlosfw transform and imager)::

    P_f(x_s) = sum_t H(x_s, t) * exp(-2 pi i f t_c) * delta_t

with t_c the bin centres ``capture.bin_centers`` (t_start + (i + 1/2) delta_t)
and f in cycles per metre of optical path. A scatterer at path length d
therefore gives P ∝ exp(-2 pi i f d); imagers focus by multiplying with
exp(+2 pi i f |x_v - x_s|).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.config import require
from nlosfw.common.errors import ConfigError
from nlosfw.transform.common import FieldOptions, check_capture, transform_capture
from nlosfw.transform.field import PhasorField
from nlosfw.transform.frequencies import (
    band_info,
    check_frequency_values,
    default_band,
    grid_spacing,
    validate_frequencies,
    wall_spacing,
)
from nlosfw.transform.interface import PhasorTransform, PhasorTransformConfig
from nlosfw.transform.temporal_dft import DftMethod


@dataclass(frozen=True)
class FFTTransformConfig(PhasorTransformConfig):
    """Options of the ``fft`` transform.

    Either an explicit ``frequencies`` list, or ``n_frequencies`` spread
    linearly over [f_min, f_max]. By default f_max is the wall grid's aliasing
    limit, 1/(2Δ) for a single laser spot and 1/(4Δ) for a confocal scan (the path
    doubles), Δ the wall grid spacing, capped at the temporal Nyquist limit; and
    f_min = f_max / 4. A band past the aliasing limit is recorded in
    the field's ``band`` (a run that images it on the wall warns once).
    """

    frequencies: tuple[float, ...] = ()
    """[1/m] Explicit frequencies (cycles per metre of path); empty: use the band below."""
    n_frequencies: int = 151
    """Number of frequencies spread linearly over the band (the thesis uses 151)."""
    f_min: float | None = None
    """[1/m] Lowest frequency of the band; default f_max / 4."""
    f_max: float | None = None
    """[1/m] Highest frequency of the band; default the aliasing limit 1/(2 m Δ) for wall
    grid spacing Δ (m = 1 single-spot, 2 confocal)."""
    grid_spacing: float | None = None
    """[m] Wall spacing Δ for the default band and the aliasing warning; default the
    capture's (set it to the spacing of a denser grid the field will be upsampled to)."""
    remove_device_legs: bool = True
    """Take the device-to-wall legs out of the phase when the capture's time axis has them."""
    method: DftMethod = DftMethod.auto
    """``fft`` needs exact DFT bins; ``direct`` is a streamed matrix product; ``auto`` picks."""

    def __post_init__(self) -> None:
        check_frequency_values(self.frequencies, "frequencies")
        require(self.n_frequencies >= 1, "n_frequencies",
                f"must be >= 1, got {self.n_frequencies}")
        for name in ("f_min", "f_max", "grid_spacing"):
            value = getattr(self, name)
            require(value is None or (math.isfinite(value) and value > 0), name,
                    f"must be a finite number > 0, got {value}")
        if self.f_min is not None and self.f_max is not None:
            require(self.f_min < self.f_max, "f_min",
                    f"empty band: f_min = {self.f_min} must be below f_max = {self.f_max}")
        require(not (self.frequencies and (self.f_min is not None or self.f_max is not None)),
                "frequencies", "give either an explicit list or a band (f_min, f_max), not both")


class FFTTransform(PhasorTransform[FFTTransformConfig]):
    """Temporal DFT of a single-spot or confocal capture at a set of frequencies.

    Exact DFT bins go through a zero-padded real FFT, other frequencies through
    a direct evaluation streamed over the time axis; both agree with a
    brute-force DFT to ~1e-12. See the module docstring for the sign convention.
    """

    config_class = FFTTransformConfig

    def frequency_count(self, n_bins: int) -> int:
        """The explicit frequencies' count, else ``n_frequencies``."""
        return len(self.config.frequencies) or self.config.n_frequencies

    def planned_frequencies(self, capture: Capture) -> np.ndarray | None:
        """:meth:`frequencies_for`."""
        return self.frequencies_for(capture)

    def frequencies_for(self, capture: Capture) -> np.ndarray:
        """The frequencies this transform uses for ``capture`` (validated; whether they
        alias on the wall grid is the field's ``band``)."""
        return self._band(capture)[0]

    def _band(self, capture: Capture) -> tuple[np.ndarray, float | None, str]:
        """(frequencies, wall spacing checked against, option named in the warning)."""
        cfg = self.config
        if cfg.frequencies:
            freqs = np.asarray(cfg.frequencies, dtype=float)
            spacing = wall_spacing(cfg.grid_spacing, capture, required=False)
            option = "transform.frequencies"
            return validate_frequencies(freqs, capture.delta_t, spacing, option,
                                        capture.kind, warn=False), spacing, option
        spacing = (cfg.grid_spacing if cfg.grid_spacing is not None
                   else grid_spacing(capture.sensor_grid_xyz))
        try:
            lo, hi = default_band(spacing, capture.delta_t, cfg.f_min, cfg.f_max, capture.kind)
        except ConfigError as err:
            raise err.within("transform") from None
        option = "transform.f_max" if cfg.f_max is not None else "transform.f_min"
        return validate_frequencies(np.linspace(lo, hi, cfg.n_frequencies), capture.delta_t,
                                    spacing, option, capture.kind, warn=False), spacing, option

    def transform(self, capture: Capture) -> PhasorField:
        """The phasor field of ``capture`` (layout [frequency, y, x], no weights)."""
        check_capture(capture, "fft")
        freqs, spacing, option = self._band(capture)
        return transform_capture(capture, freqs, FieldOptions(
            transform="fft", method=self.config.method,
            remove_device_legs=self.config.remove_device_legs,
            band=band_info(freqs, spacing, capture.kind, option)))

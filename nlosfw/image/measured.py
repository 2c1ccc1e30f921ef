"""Fields for imaging measured captures with the transient imagers (``lct``, ``fk``, ``fbp``).

* :func:`measured_field`: the capture's DFT bins in :data:`~nlosfw.image.transient.MEASURED_BAND`
  (0.4-60 cycles/m of path), the band that gives the classical imagers clean images of the
  Stanford LCT captures;
* :func:`histogram_field`: every DFT bin of the capture, so that a transient imager sees
  the measured histograms at their native bin width (less their mean), as the authors
  image them: the reference picture beside band-limited sources.
"""

from __future__ import annotations

import dataclasses

from nlosfw.capture.data import Capture
from nlosfw.image.transient import (
    MEASURED_BAND,
    full_band_frequencies,
    measured_band_frequencies,
)
from nlosfw.transform.fft import FFTTransform, FFTTransformConfig
from nlosfw.transform.field import PhasorField


def measured_field(capture: Capture, band: tuple[float, float] = MEASURED_BAND) -> PhasorField:
    """The capture's phasor field at its DFT bins within ``band`` (cycles/m)."""
    freqs = measured_band_frequencies(capture.n_bins, capture.delta_t, band)
    return FFTTransform(FFTTransformConfig(frequencies=tuple(float(f) for f in freqs))
                        ).transform(capture)


def histogram_field(capture: Capture, config: FFTTransformConfig | None = None) -> PhasorField:
    """The capture's phasor field at every positive DFT bin: its histograms as measured
    (``config``: the ``fft`` transform's other options, e.g. a run's)."""
    freqs = tuple(float(f) for f in full_band_frequencies(capture.n_bins, capture.delta_t))
    base = FFTTransformConfig() if config is None else config
    return FFTTransform(dataclasses.replace(base, frequencies=freqs, f_min=None, f_max=None)
                         ).transform(capture)

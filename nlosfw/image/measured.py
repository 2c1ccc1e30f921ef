"""Fields for imaging measured captures with the transient imagers (``lct``, ``fk``, ``fbp``).

* :func:`measured_field`: the capture's DFT bins in :data:`~nlosfw.image.transient.MEASURED_BAND`
  (0.4-60 cycles/m of path), the band that gives the classical imagers clean images of the
  Stanford LCT captures;
* :func:`histogram_field`: every DFT bin of the capture, so that a transient imager sees
  the measured histograms at their native bin width (less their mean), as the authors
  image them: the reference picture beside band-limited sources.
"""

from __future__ import annotations

from nlosfw.capture.data import Capture
from nlosfw.image.transient import (
    MEASURED_BAND,
    full_band_frequencies,
    measured_band_frequencies,
)
from nlosfw.transform.common import FieldOptions, check_capture, transform_capture
from nlosfw.transform.fft import FFTTransform, FFTTransformConfig
from nlosfw.transform.field import PhasorField
from nlosfw.transform.frequencies import band_info

#: The option a reference field's band metadata names (its band is every DFT bin, never
#: checked against the wall grid: the transient imagers image no wall band).
HISTOGRAM_BAND = "every DFT bin of the capture"


def measured_field(capture: Capture, band: tuple[float, float] = MEASURED_BAND) -> PhasorField:
    """The capture's phasor field at its DFT bins within ``band`` (cycles/m)."""
    freqs = measured_band_frequencies(capture.n_bins, capture.delta_t, band)
    return FFTTransform(FFTTransformConfig(frequencies=tuple(float(f) for f in freqs))
                        ).transform(capture)


def histogram_field(capture: Capture, config: FFTTransformConfig | None = None) -> PhasorField:
    """The capture's phasor field at every positive DFT bin: its histograms as measured
    (``config``: the ``fft`` transform's other options, e.g. a run's). The band is the whole
    DFT's, so no aliasing warning is logged: time-domain imagers image no wall band."""
    check_capture(capture, "fft")
    base = FFTTransformConfig() if config is None else config
    freqs = full_band_frequencies(capture.n_bins, capture.delta_t)
    return transform_capture(capture, freqs, FieldOptions(
        transform="fft", method=base.method, remove_device_legs=base.remove_device_legs,
        band=band_info(freqs, None, capture.kind, HISTOGRAM_BAND)))

"""The reference picture of a run: whether the capture's histograms are imaged at their
native bin width, and what it costs.

Every source a run scores is imaged from the same band (for a capture file and a
time-domain imager, the measured-capture band of :mod:`nlosfw.image.measured`), so scores
stay fair. Beside them the reconstruct stage images the whole capture's histograms as
measured (every DFT bin, :func:`~nlosfw.image.measured.histogram_field`), with the run's
imager on the run's planes: the picture the authors' code makes. It is never scored
(:class:`~nlosfw.pipeline.results.Reconstructions` keeps it apart from the sources);
``reconstruction.histogram_reference`` chooses when it is made (:func:`reference_reason`),
and the memory it needs (:func:`reference_bytes`, :func:`memory_reason`) whether it can be.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from nlosfw.capture.data import Capture
from nlosfw.common.files import format_bytes
from nlosfw.common.memory import available_memory
from nlosfw.evaluation.count_splitting import CountSplit
from nlosfw.image.transient import full_band_frequencies

#: The reference picture's name in the run's files: ``figures/<view>_native-bins.png`` and
#: ``reconstructions/native-bins.hdf5`` (not an identifier, so no ``compare`` label is it).
REFERENCE = "native-bins"

#: What the reference picture is, for titles and captions.
REFERENCE_TITLE = "reference: the measured histograms (native bins)"

#: Arrays of the padded volume's size a time-domain imager holds at once (its spectrum,
#: the kernel's or the Stolt interpolation's operands, temporaries): on the generous side,
#: the peak tracemalloc measures for lct and fk is 0.5 and 0.8 of the estimate
#: (tests/evaluation/test_histogram_reference.py).
_VOLUMES_AT_ONCE = 8


def reference_capture(capture: Capture, count_split: CountSplit | None = None) -> Capture:
    """The histograms as measured: the run's ``capture``, or with count splitting half A's
    and half B's counts added back together."""
    return capture if count_split is None else count_split.whole


def reference_reason(choice: bool | None, imager: str, time_domain: bool, from_file: bool,
                     capture: Capture) -> str | None:
    """Why the run makes no reference picture (None: it makes one), in a few words.

    ``choice``: ``reconstruction.histogram_reference``; ``imager``: the imager's name,
    ``time_domain``: whether it images the whole time grid (lct, fk, fbp) rather than a
    band; ``from_file``: whether ``capture`` (the run's) was read from a file.
    """
    if choice is False:
        return "reconstruction.histogram_reference=false"
    if not time_domain:
        return f"imager {imager} images a band, not the histograms"
    if choice is None and not from_file:
        return "a simulated capture (reconstruction.histogram_reference=true makes one)"
    if not capture.is_time_domain:
        return "the capture is stored in frequency, with no histograms"
    if not capture.is_confocal:
        return f"imager {imager} images confocal captures only"
    return None


def memory_reason(needed: float, allow_large: bool) -> str | None:
    """Why the reference picture, needing ``needed`` bytes, is not made (None: it fits the
    available memory, or ``limits.allow_large`` makes it anyway)."""
    room = available_memory()
    if room is None or needed <= room or allow_large:
        return None
    return (f"imaging the histograms at native bins needs about {format_bytes(needed)}, but "
            f"{format_bytes(room)} are available (limits.allow_large=true makes it anyway)")


def reference_bytes(capture: Capture, depths: np.ndarray, options: object) -> float:
    """Bytes a time-domain imager (``options``: its config) holds at once imaging the whole
    band of ``capture`` at ``depths``: its padded volume, time samples 1/(k f_max) apart
    (k: ``samples_per_wavelength``) to the farthest path, twice over in time and each wall
    axis (capped at ``max_bins`` along v for the light-cone imagers), and the transient."""
    freqs = full_band_frequencies(capture.n_bins, capture.delta_t)
    per_wavelength = float(getattr(options, "samples_per_wavelength", 4.0))
    dt = 1.0 / (per_wavelength * float(freqs.max()))
    points = capture.sensor_points
    reach = float(np.hypot(np.ptp(points[:, 0]), np.ptp(points[:, 1])))
    far = math.hypot(float(np.max(depths)) + 2 * dt, reach)
    n = math.ceil(2 * far / dt) + 1
    steps = n
    max_bins = getattr(options, "max_bins", None)
    if isinstance(max_bins, int):     # the light cone's v = d^2 axis
        near = max(float(np.min(depths)), dt / 2)
        steps = min(max_bins, max(n, math.ceil(far * far / (near * dt))))
    walls = points.shape[0]
    padded = 8.0 * scipy.fft.next_fast_len(2 * steps) * 4 * walls        # complex64
    return (_VOLUMES_AT_ONCE * padded + 8.0 * n * walls + 16.0 * n * freqs.size
            + 16.0 * freqs.size * walls)

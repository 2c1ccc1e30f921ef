"""The reference picture of a run: the capture's histograms imaged at their native bin width.

Every source a run scores is imaged from the same band (for a capture file and a
time-domain imager, the measured-capture band of :mod:`nlosfw.image.measured`), so scores
stay fair. Beside them the reconstruct stage images the whole capture's histograms as
measured (every DFT bin, :func:`~nlosfw.image.measured.histogram_field`), with the run's
imager on the run's planes: the picture the authors' code makes. It is never scored
(:class:`~nlosfw.pipeline.results.Reconstructions` keeps it apart from the sources);
``reconstruction.histogram_reference`` chooses when it is made (:func:`reference_reason`).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import scipy.fft

from nlosfw.capture.data import Capture
from nlosfw.common.files import format_bytes
from nlosfw.common.logs import FILE_ONLY
from nlosfw.image.measured import histogram_field
from nlosfw.image.transient import full_band_frequencies
from nlosfw.pipeline.budget import available_memory
from nlosfw.pipeline.context import StageContext
from nlosfw.pipeline.results import CaptureResult
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

#: The reference picture's name in the run's files: ``figures/<view>_native-bins.png`` and
#: ``reconstructions/native-bins.hdf5`` (not an identifier, so no ``compare`` label is it).
REFERENCE = "native-bins"

#: What the reference picture is, for titles and captions.
REFERENCE_TITLE = "reference: the measured histograms (native bins)"

#: Arrays of the padded volume's size a time-domain imager holds at once (its spectrum,
#: the kernel's or the Stolt interpolation's operands, temporaries): on the generous side,
#: the peak tracemalloc measures for lct and fk is 0.5 and 0.8 of the estimate
#: (tests/test_histogram_reference.py).
_VOLUMES_AT_ONCE = 8


def reference_capture(result: CaptureResult) -> Capture:
    """The histograms as measured: the run's capture, or with count splitting half A's and
    half B's counts added back together."""
    if result.thinning is None:
        return result.capture
    a, b = result.thinning.a, result.thinning.b
    return a.replace(H=np.asarray(a.H) + np.asarray(b.H))


def reference_reason(run: StageContext, result: CaptureResult) -> str | None:
    """Why the run makes no reference picture (None: it makes one), in a few words."""
    choice = run.plan.settings.reconstruction.histogram_reference
    imager = run.plan.imager
    if choice is False:
        return "reconstruction.histogram_reference=false"
    if not run.plan.imager_needs.time_domain:
        return f"imager {imager.name} images a band, not the histograms"
    if choice is None and result.source != "file":
        return "a simulated capture (reconstruction.histogram_reference=true makes one)"
    capture = result.capture
    if not capture.is_time_domain:
        return "the capture is stored in frequency, with no histograms"
    if not capture.is_confocal:
        return f"imager {imager.name} images confocal captures only"
    return None


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


def reference_field(run: StageContext, result: CaptureResult,
                    voxels: np.ndarray) -> PhasorField | None:
    """The field of the capture's histograms at their native bin width (every positive DFT
    bin, the run's ``fft`` transform options kept), carrying the capture's imaging hints;
    None, with the reason in the log, when the run makes no reference picture (run.log
    only where it does not apply, a warning when ``reconstruction.histogram_reference``
    asked for one)."""
    settings = run.plan.settings
    asked = settings.reconstruction.histogram_reference is True
    reason = reference_reason(run, result)
    if reason is not None:
        _no_reference(asked, "%s", reason)
        return None
    capture = reference_capture(result)
    depths = np.unique(np.asarray(voxels, dtype=float)[..., 2])
    needed = reference_bytes(capture, depths, run.plan.imager.plugin.config)
    room = available_memory()
    if room is not None and needed > room and not settings.limits.allow_large:
        _no_reference(asked, "imaging the histograms at native bins needs about %s, but %s "
                      "are available (limits.allow_large=true makes it anyway)",
                      format_bytes(needed), format_bytes(room))
        return None
    transform = run.plan.transform.plugin
    field = histogram_field(capture, transform.config
                            if isinstance(transform, FFTTransform) else None)
    if field.imaging_hints is None and result.capture.imaging_hints is not None:
        field = field.replace(imaging_hints=result.capture.imaging_hints)
    log.info("reference picture: the histograms at native bins, %d frequencies to %.4g "
             "cycles/m (estimated memory %s; not scored)", field.n_frequencies,
             float(field.frequencies.max()), format_bytes(needed))
    return field


def _no_reference(asked: bool, reason: str, *args: object) -> None:
    """Log why no reference picture is made: a console warning when
    ``reconstruction.histogram_reference=true`` asked for one, else run.log only."""
    log.log(logging.WARNING if asked else logging.INFO, "no reference picture: " + reason,
            *args, extra=None if asked else FILE_ONLY)

"""Automatic depth planes: spaced by the band's depth resolution over the depths with signal.

The phasor field at frequency f (cycles per metre of path) propagates into the
hidden volume as a wave of spatial wavelength 1/(m f): m = 1 for a single laser
spot (only the sensor leg is the propagated wave; the laser leg is a known phase),
m = 2 for a confocal scan (laser and sensor legs move together: a point at depth
z is at path 2z, so the wave in the volume has half the path wavelength). Planes a
quarter of the shortest such wavelength apart sample the image finely enough for
any frequency of the band:

    step = 1 / (4 m f_max)        (λ_min / 4 single-spot, λ_min / 8 confocal)

With the automatic band (f_max = 1/(2 m Δ), see
:func:`nlosfw.transform.frequencies.spatial_limit`) this is Δ/2 for both kinds.
The planes span :func:`depth_span`: the capture's ground truth, else the hidden
volume a Zaragoza file declares, else the part of its time profile where the
signal stands above the background (:mod:`nlosfw.capture.signal`; device legs
removed; a path t reaches at most t/2 deep).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.signal import signal_depth_range
from nlosfw.common.errors import ConfigError

log = logging.getLogger(__name__)

#: Most planes the automatic rule chooses (beyond it the step grows, with an INFO line).
MAX_AUTOMATIC_PLANES = 512


def depth_step(f_max: float, kind: CaptureKind) -> float:
    """1 / (4 m f_max): a quarter of the shortest wavelength of the wave in the volume (m)."""
    m = 2 if kind is CaptureKind.CONFOCAL else 1
    return 1.0 / (4.0 * m * float(f_max))


def automatic_depths(span: tuple[float, float], f_max: float, kind: CaptureKind,
                     max_planes: int = MAX_AUTOMATIC_PLANES) -> np.ndarray:
    """Planes from ``span[0]`` to ``span[1]`` at most :func:`depth_step` apart (both ends
    included; at most ``max_planes``)."""
    near, far = float(span[0]), float(span[1])
    n = automatic_count(span, f_max, kind)
    if n > max_planes:
        log.info("automatic depths: %d planes %.4g m apart would span %.4g-%.4g m; using %d",
                 n, depth_step(f_max, kind), near, far, max_planes)
        n = max_planes
    return np.linspace(near, far, n)


def automatic_count(span: tuple[float, float], f_max: float, kind: CaptureKind) -> int:
    """How many planes :func:`automatic_depths` puts over ``span`` before its cap."""
    step = depth_step(f_max, kind)
    return max(2, math.ceil((float(span[1]) - float(span[0])) / step - 1e-9) + 1)


def depth_span(capture: Capture) -> tuple[float, float]:
    """The automatic depth range: depths covering the hidden scene from the ground truth,
    else the hidden volume a Zaragoza file declares, else where the capture's signal rises
    above its background (:func:`nlosfw.capture.signal.signal_depth_range`: robust to dark
    counts and late background, unlike the last bin with counts), else 0.3-2 m.

    A run's planes follow, in this order: ``reconstruction.depths``, then
    ``reconstruction.depth_range``, then this range."""
    if not isinstance(capture, Capture):
        raise ConfigError("capture", f"depth_span needs a Capture, got "
                                     f"{type(capture).__name__}")
    truth = (capture.scene_info.get("ground_truth") or {}).get("depth")
    if truth is not None:
        depth = np.asarray(truth, dtype=float)
        hit = depth[depth > 0]
        if hit.size:
            lo, hi = float(hit.min()), float(hit.max())
            margin = max(0.15, 0.25 * (hi - lo))
            return max(0.05, lo - margin), hi + margin
    volume = capture.scene_info.get("volume") or {}
    if volume.get("center") is not None and volume.get("size") is not None:
        centre = float(np.asarray(volume["center"], dtype=float).reshape(-1)[2])
        half = float(np.asarray(volume["size"], dtype=float).reshape(-1)[-1]) / 2
        if centre - half > 0:
            return centre - half, centre + half
    found = signal_depth_range(capture)
    return (0.3, 2.0) if found is None else found

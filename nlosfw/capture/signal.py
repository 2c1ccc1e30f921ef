"""Where a capture's signal is: the part of its time profile above the background.

Measured histograms hold more than the hidden scene: dark counts and ambient light (a flat
floor over every bin), the tail of the direct reflection in the first bins after the gate,
and weak late inter-reflections. The last bin with counts is therefore not where the scene
ends (it is the end of the histogram), and depths derived from it run far past the object,
where a radiometric gain (t^3 for 1/r^4) makes the late noise the brightest part of an image.

:func:`signal_path_range` smooths the time profile (the histograms summed over the wall),
estimates its background as the lower of the medians of the early bins (after the gate) and
of the tail, its noise from the tail's spread, and returns the first and last path where the
profile rises above the background by the larger of ``min_snr`` noise deviations and
``fraction`` of the peak's excess. :func:`signal_depth_range` turns that into depths
(device legs removed; a path t reaches at most t/2 deep, and the nearest point of a confocal
or single-spot capture at least a fraction of it).
"""

from __future__ import annotations

import numpy as np

from nlosfw.capture.data import Capture

#: Fraction of the peak excess over the background that counts as signal.
SIGNAL_FRACTION = 0.03
#: Noise deviations (of the smoothed tail) above the background that count as signal.
SIGNAL_MIN_SNR = 6.0
#: Share of the (non-zero) histogram taken as its early part and as its tail.
_EDGE_SHARE = 0.15


def time_profile(capture: Capture) -> np.ndarray:
    """The histograms summed over every wall point, one value per bin (float64), summed in
    place: a preprocessed capture's histograms are a strided view, which a reshape would
    copy whole."""
    h = np.asarray(capture.H)
    return h.sum(axis=tuple(range(1, h.ndim)), dtype=np.float64)


def signal_bins(profile: np.ndarray, fraction: float = SIGNAL_FRACTION,
                min_snr: float = SIGNAL_MIN_SNR) -> tuple[int, int] | None:
    """[first, last] bin of ``profile`` where the signal stands above the background (see
    the module docstring); None when nothing does."""
    p = np.asarray(profile, dtype=np.float64)
    nonzero = np.flatnonzero(p != 0)
    if nonzero.size == 0:
        return None
    start, stop = int(nonzero[0]), int(nonzero[-1]) + 1
    live = p[start:stop]
    width = max(1, live.size // 100)
    smooth = np.convolve(live, np.ones(width) / width, mode="same")
    edge = max(1, int(_EDGE_SHARE * live.size))
    early, tail = smooth[:edge], smooth[-edge:]
    background = min(float(np.median(early)), float(np.median(tail)))
    noise = 1.4826 * float(np.median(np.abs(tail - np.median(tail))))
    excess = smooth - background
    peak = float(excess.max())
    if not peak > 0:
        return None
    above = np.flatnonzero(excess > max(fraction * peak, min_snr * noise))
    if above.size == 0:
        return None
    return start + int(above[0]), start + int(above[-1])


def signal_path_range(capture: Capture) -> tuple[float, float] | None:
    """[first, last] path (m, from the wall: device legs removed) of the capture's signal;
    None when its histograms hold none."""
    found = signal_bins(time_profile(capture))
    if found is None:
        return None
    legs = float(np.mean(capture.geometry.device_path(capture.sensor_points)))
    centres = capture.bin_centers
    half_bin = capture.delta_t / 2
    return float(centres[found[0]] - half_bin - legs), float(centres[found[1]] + half_bin - legs)


def signal_depth_range(capture: Capture) -> tuple[float, float] | None:
    """Depths (m) that can hold the capture's signal: from 0.8 x half the first path to half
    the last (a path t reaches at most t/2 deep); at least 5 cm and 30 cm. None when the
    histograms hold no signal."""
    paths = signal_path_range(capture)
    if paths is None:
        return None
    first, last = paths
    return max(0.05, 0.8 * first / 2), max(0.3, last / 2)

"""Preprocessing along the time axis of a capture: gate, crop, per-pixel delays and
background; pure functions, each returning a new capture."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.preprocess_options import METRES_PER_PS, Gate, TimeCrop
from nlosfw.capture.scan_grid import _need_grid
from nlosfw.common.errors import ConfigError


def gate_bins(capture: Capture, gate: Gate, option: str = "capture.gate") -> int:
    """How many leading bins ``gate`` zeroes; ConfigError if it reaches the end."""
    if gate.bins is not None:
        n, name, value = int(gate.bins), "bins", f"{gate.bins} bins"
    else:
        assert gate.metres is not None
        n = max(0, _bin_at(capture, gate.metres, np.ceil, -1e-9))
        name, value = "metres", f"{gate.metres} m"
    if n >= capture.n_bins:
        end = capture.t_start + capture.n_bins * capture.delta_t
        raise ConfigError(f"{option}.{name}",
                          f"{value} is past the end of the histogram ({capture.n_bins} bins, "
                          f"path {capture.t_start:.4g} to {end:.4g} m); valid: fewer than "
                          f"{capture.n_bins} bins (0: no gate)")
    return n


def _bin_at(capture: Capture, metres: float, rounding: Callable[[float], float],
            nudge: float) -> int:
    """The bin boundary at optical path ``metres`` (rounded by ``rounding`` after ``nudge``),
    clipped to one bin beyond either end of the histogram: a path of 1e308 m is past the end,
    not an integer too large to hold (and the check that compares it must not fail)."""
    position = (metres - capture.t_start) / capture.delta_t + nudge
    return int(rounding(np.clip(position, -1.0, capture.n_bins + 1.0)))


def zero_before(capture: Capture, n: int) -> Capture:
    """A copy of ``capture`` with its first ``n`` bins zeroed."""
    H = np.array(capture.H, copy=True)
    H[:n] = 0
    return capture.replace(H=H)


def crop_bins(capture: Capture, crop: TimeCrop, option: str = "capture.time_crop"
              ) -> tuple[int, int]:
    """The bins [start, stop) ``crop`` keeps; ConfigError unless they lie in the histogram."""
    if crop.bins is not None:
        start, stop = (int(b) for b in crop.bins)
        name = "bins"
    else:
        assert crop.metres is not None
        lo, hi = crop.metres
        start = max(0, _bin_at(capture, lo, np.floor, 1e-9))
        stop = min(capture.n_bins, _bin_at(capture, hi, np.ceil, -1e-9))
        name = "metres"
    if not 0 <= start < stop <= capture.n_bins:
        end = capture.t_start + capture.n_bins * capture.delta_t
        raise ConfigError(f"{option}.{name}",
                          f"keeps bins [{start}, {stop}), outside the histogram ({capture.n_bins}"
                          f" bins, path {capture.t_start:.4g} to {end:.4g} m); valid: 0 <= "
                          f"start < stop <= {capture.n_bins}")
    return start, stop


def crop_time(capture: Capture, start: int, stop: int) -> Capture:
    """The bins [start, stop) of ``capture``; ``t_start`` moves to the new first bin."""
    return capture.replace(H=np.array(capture.H[start:stop], copy=True),
                           t_start=capture.t_start + start * capture.delta_t)


def remove_delays(capture: Capture, delays_ps: np.ndarray, option: str = "capture.tofgrid"
                  ) -> tuple[Capture, np.ndarray]:
    """Shift each scan point's histogram left by floor(delay / bin width) bins (zeros enter
    at the end; the authors' MATLAB code wraps them around instead); returns the capture
    and the shifts (X, Y) in bins."""
    _need_grid(capture, option)
    delays = np.asarray(delays_ps, dtype=float)
    if delays.shape != capture.grid_shape:
        raise ConfigError(option, f"per-pixel delays of shape {list(delays.shape)} do not match "
                                  f"the scan grid {list(capture.grid_shape)}")
    if not np.all(np.isfinite(delays)):
        raise ConfigError(option, "per-pixel delays contain NaN or inf")
    bin_ps = capture.delta_t / METRES_PER_PS
    shifts = np.floor(delays / bin_ps + 1e-9).astype(np.int64)
    n = capture.n_bins
    H = capture.H
    out = np.zeros(H.shape, dtype=H.dtype)
    for s in np.unique(shifts):
        mask = shifts == s
        if 0 <= s < n:
            out[: n - s, mask] = H[s:, mask]
        elif -n < s < 0:
            out[-s:, mask] = H[: n + s, mask]
    return capture.replace(H=out), shifts


def subtract_background(capture: Capture, background: Capture) -> Capture:
    """``capture`` minus ``background`` bin by bin (same shape, bins and scan points)."""
    check_background(capture, background)
    H = capture.H.astype(np.result_type(capture.H, background.H), copy=True)
    H -= background.H
    if not np.any(H):
        raise ConfigError("capture.background", "subtracting it leaves nothing: it equals the "
                                                "capture (give the background measurement)")
    return capture.replace(H=H)


def check_background(capture: Capture, background: Capture) -> None:
    """A ConfigError for ``capture.background`` unless ``background`` has ``capture``'s
    shape, time axis and scan points (what :func:`subtract_background` needs)."""
    if background.H.shape != capture.H.shape:
        raise ConfigError("capture.background", f"shape {list(background.H.shape)} does not "
                                                f"match the capture's {list(capture.H.shape)}")
    if not (np.isclose(background.delta_t, capture.delta_t, rtol=1e-6)
            and np.isclose(background.t_start, capture.t_start, rtol=0, atol=1e-9)):
        raise ConfigError("capture.background", f"time axis (bin {background.delta_t:.6g} m from "
                                                f"{background.t_start:.6g} m) differs from the "
                                                f"capture's (bin {capture.delta_t:.6g} m from "
                                                f"{capture.t_start:.6g} m)")
    if not np.allclose(background.sensor_grid_xyz, capture.sensor_grid_xyz, atol=1e-6):
        raise ConfigError("capture.background", "its scan points differ from the capture's")


"""Where the hidden scene lies, from a capture alone: the depths worth imaging."""

from __future__ import annotations

import numpy as np

from nlosfw.capture.data import Capture


def hidden_depth_range(capture: Capture) -> tuple[float, float]:
    """(near, far) depths (m) covering the hidden scene.

    From the scene's ground truth when the capture carries one (with a margin),
    else the hidden volume a Zaragoza file declares, else the span of the signal
    in time with the device legs removed (a path of length t reaches at most t/2
    deep: wall -> point -> wall).
    """
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
    profile = capture.H.reshape(capture.n_bins, -1).sum(axis=1)
    nonzero = (np.flatnonzero(profile > 1e-3 * profile.max()) if profile.max() > 0
               else np.zeros(0, dtype=np.int64))
    if len(nonzero) == 0:
        return 0.3, 2.0
    legs = float(np.mean(capture.geometry.device_path(capture.sensor_points)))
    first, last = capture.bin_centers[[nonzero[0], nonzero[-1]]] - legs
    return max(0.05, 0.8 * float(first) / 2), max(0.3, float(last) / 2)

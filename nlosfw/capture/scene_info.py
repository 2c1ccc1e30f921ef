"""The parts of a capture's free ``scene_info`` that nlosfw reads, checked when read.

``scene_info`` is free metadata, but nlosfw reads two parts of it: the ground truth a
simulator records (``ground_truth.depth`` and ``ground_truth.albedo``, maps (X, Y) with
-1 where nothing is hit) and the hidden volume a Zaragoza file declares
(``volume.center``, ``volume.size``). A malformed one is refused with one line naming
the key when the capture is built (or read), not halfway through a run.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from nlosfw.common.errors import DataError


def check_scene_info(info: Mapping[str, object]) -> None:
    """Raise :class:`DataError` naming the key when a part nlosfw reads is malformed."""
    truth = info.get("ground_truth")
    if truth is not None:
        if not isinstance(truth, Mapping):
            raise DataError("scene_info.ground_truth: must be a mapping with depth (and "
                            f"albedo) maps, got {type(truth).__name__}")
        depth = _map(truth, "depth")
        albedo = _map(truth, "albedo")
        if depth is not None and albedo is not None and depth.shape != albedo.shape:
            raise DataError(f"scene_info.ground_truth.albedo: shape {albedo.shape} does not "
                            f"match the depth map's {depth.shape}")
    volume = info.get("volume")
    if volume is not None:
        if not isinstance(volume, Mapping):
            raise DataError("scene_info.volume: must be a mapping (center, size, rotation), "
                            f"got {type(volume).__name__}")
        _numbers(volume, "center", (3,))
        _numbers(volume, "size", (1, 3))


def _array(value: Any, key: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise DataError(f"scene_info.{key}: must hold numbers only (a regular array)"
                        ) from None
    if not np.all(np.isfinite(arr)):
        raise DataError(f"scene_info.{key}: contains NaN or inf")
    return arr


def _map(truth: Mapping[str, object], name: str) -> np.ndarray | None:
    if truth.get(name) is None:
        return None
    arr = _array(truth[name], f"ground_truth.{name}")
    if arr.ndim != 2 or arr.size == 0:
        raise DataError(f"scene_info.ground_truth.{name}: must be a non-empty 2-D map (X, Y), "
                        f"got shape {arr.shape}")
    return arr


def _numbers(volume: Mapping[str, object], name: str, sizes: tuple[int, ...]) -> None:
    if volume.get(name) is None:
        return
    arr = _array(volume[name], f"volume.{name}").reshape(-1)
    if arr.size not in sizes:
        raise DataError(f"scene_info.volume.{name}: must have {' or '.join(map(str, sizes))} "
                        f"numbers, got {arr.size}")

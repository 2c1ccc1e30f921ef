"""The titles of a run's figures and page, built in one place (no matplotlib here)."""

from __future__ import annotations

from pathlib import Path

from nlosfw.common.text import visible
from nlosfw.pipeline.metrics import RunInfo
from nlosfw.pipeline.results import CaptureResult
from nlosfw.pipeline.settings import NO_MODEL


def run_title(info: RunInfo, capture: CaptureResult | None = None) -> str:
    """What ran, in one line: the capture file and its format (or the scene and its
    simulator), the model (none for ``model=none``) and the imager; every figure's title.

    ``capture data_diffuse_s.mat (format lct) · imager fft``."""
    if capture is not None and capture.path is not None:
        source = f"capture {capture.path.name} (format {capture.format})"
    elif info.capture_file is not None:
        source = f"capture {Path(info.capture_file).name} (format {info.capture_format})"
    else:
        simulator = info.simulator if capture is None else capture.simulator
        source = f"scene {info.scene} (simulator {simulator})"
    model = "" if info.model == NO_MODEL else f" · model {info.model}"
    return visible(f"{source}{model} · imager {info.imager}")

"""Where the shared real captures are: ``$NLOSFW_REAL_DATA`` if set, else
``../shared/data/real`` beside the repository root (optional data: tests skip without it)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REAL_DIR = Path(os.environ.get("NLOSFW_REAL_DATA")
                or Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real")
#: The three Stanford LCT captures of ../shared/data/real (README there).
LCT_CAPTURES = ("data_diffuse_s", "data_resolution_chart_40cm", "data_dot_chart_40cm")


def real_capture(name: str) -> Path:
    """The path of shared capture ``name`` (.mat), or skip the test with the reason."""
    path = REAL_DIR / f"{name}.mat"
    if not path.is_file():
        pytest.skip(f"shared capture {path} absent (real data is optional; set "
                    "NLOSFW_REAL_DATA to its folder)")
    return path

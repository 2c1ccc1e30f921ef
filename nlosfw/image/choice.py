"""Which imager images a capture of a given geometry: the rule a run follows with
``reconstruction.pick_imager=true`` (what ``python -m nlosfw image FILE`` does when no
``imager`` option is given).

* a confocal scan on a regular wall grid: ``lct``, the light-cone transform with the
  settings estimated from the data (:mod:`nlosfw.image.data_settings`). Compared with
  ``fft``, ``fk`` and ``fbp`` on the shared Stanford LCT captures (a diffuse letter, two
  retroreflective charts) by the normalised cross-correlation of the front view with the
  authors' own LCT reconstruction, the brightest voxel's depth against theirs, and the
  front view's sharpness, it matches the authors' picture best on each capture, its
  brightest depth within a centimetre of theirs; ``fft`` images only the band the wall's
  sampling allows: a sparser front view, further from the authors';
* anything else (a single laser spot, a scan off a regular grid): ``fft``, the phasor-field
  imager, which images every geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.image.plane_convolution import grid_layout

#: The imager of a confocal scan on a regular grid, and of every other capture.
CONFOCAL_GRID_IMAGER = "lct"
OTHER_IMAGER = "fft"


@dataclass(frozen=True)
class Pick:
    """The imager picked for a capture and the one line that says why."""

    name: str
    why: str


def picked_imager(kind: CaptureKind, regular_grid: bool) -> Pick:
    """The imager for a capture of ``kind`` scanned on a regular wall grid or not."""
    if kind is CaptureKind.CONFOCAL and regular_grid:
        return Pick(CONFOCAL_GRID_IMAGER, f"imager {CONFOCAL_GRID_IMAGER} picked for a "
                    "confocal scan on a regular grid (the closest to the authors' LCT on "
                    "measured confocal captures); imager=NAME chooses another")
    what = ("a confocal scan off a regular grid" if kind is CaptureKind.CONFOCAL
            else f"a {kind.value} capture")
    return Pick(OTHER_IMAGER, f"imager {OTHER_IMAGER} picked for {what} (the phasor-field "
                "imager images every geometry); imager=NAME chooses another")


def picked_for(capture: Capture) -> Pick:
    """:func:`picked_imager` for ``capture``'s kind and sensor grid."""
    return picked_imager(capture.kind, grid_layout(capture.sensor_grid_xyz) is not None)

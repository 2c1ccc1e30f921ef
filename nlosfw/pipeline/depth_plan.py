"""The one rule for a run's depths: the range that bounds a field model's own search for
the hidden scene and the planes every field is imaged on.

The range, in this order of precedence: the near and far of ``reconstruction.depths``
(when planes are given), else ``reconstruction.depth_range``, else the automatic range of
the capture (:func:`nlosfw.image.depths.depth_span`: its ground truth, the hidden volume
a file declares, where its time profile holds signal). The planes: ``depths`` when given,
else ``n_depths`` planes evenly over the range, else planes a quarter of the band's
shortest wavelength in the volume apart over it (:func:`~nlosfw.image.depths.automatic_depths`).
The plan holds the rule (:class:`DepthPlan`, from the settings); the capture, known once
the capture stage has it, supplies the data; this module alone decides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.image.depths import (
    MAX_AUTOMATIC_PLANES,
    automatic_count,
    automatic_depths,
    depth_span,
)
from nlosfw.image.reconstruction import wall_voxels
from nlosfw.pipeline.settings import ReconstructionSettings
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True)
class DepthPlan:
    """A run's depth rule (see the module's documentation)."""

    depths: tuple[float, ...] = ()
    """[m] The planes given (empty: automatic)."""
    depth_range: tuple[float, float] | None = None
    """[m] Near and far given (None: the capture's automatic range)."""
    n_depths: int | None = None
    """Planes over the range (None: by the band's depth resolution)."""

    @classmethod
    def of(cls, settings: ReconstructionSettings) -> DepthPlan:
        """The rule the reconstruction settings give."""
        return cls(depths=tuple(float(d) for d in settings.depths),
                   depth_range=None if settings.depth_range is None
                   else (float(settings.depth_range[0]), float(settings.depth_range[1])),
                   n_depths=settings.n_depths)

    @property
    def given(self) -> tuple[float, float] | None:
        """The range the settings alone decide (None: the capture's automatic range)."""
        if self.depths:
            return min(self.depths), max(self.depths)
        return self.depth_range

    def span(self, capture: Capture) -> tuple[float, float]:
        """[m] The nearest and farthest depth of the run for ``capture``."""
        near, far = self.given or depth_span(capture)
        return float(near), float(far)

    def planes(self, capture: Capture, field: PhasorField) -> np.ndarray:
        """[m] The depth planes every field of ``capture`` is imaged on (``field``: the
        capture's, whose band sets the automatic spacing)."""
        if self.depths:
            return np.asarray(self.depths, dtype=float)
        span = self.span(capture)
        if self.n_depths is not None:
            return np.linspace(span[0], span[1], self.n_depths)
        return automatic_depths(span, float(field.frequencies.max()), field.geometry.kind)

    def count(self, span: tuple[float, float], f_max: float | None, kind: CaptureKind) -> int:
        """How many planes :meth:`planes` gives over ``span`` for a band up to ``f_max``
        (None: unknown, the automatic rule's most), without making them."""
        if self.depths:
            return len(self.depths)
        if self.n_depths is not None:
            return self.n_depths
        if f_max is None:
            return MAX_AUTOMATIC_PLANES
        return min(MAX_AUTOMATIC_PLANES, automatic_count(span, f_max, kind))

    def voxels(self, capture: Capture, field: PhasorField) -> np.ndarray:
        """The voxels: :meth:`planes` on the wall's grid."""
        return wall_voxels(field, self.planes(capture, field))

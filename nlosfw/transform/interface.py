"""The phasor-transform interface: a transient capture in, a phasor field out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, TypeVar

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.config import Configurable
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True)
class PhasorTransformConfig:
    """Options shared by every phasor transform (none yet)."""


TransformConfigT = TypeVar("TransformConfigT", bound=PhasorTransformConfig)


class PhasorTransform(Configurable[TransformConfigT], ABC):
    """Turns a time-domain :class:`Capture` into a :class:`PhasorField`."""

    config_class: ClassVar[type] = PhasorTransformConfig

    @abstractmethod
    def transform(self, capture: Capture) -> PhasorField:
        """The phasor field of ``capture`` at this transform's frequencies."""

    def planned_frequencies(self, capture: Capture) -> np.ndarray | None:
        """The frequencies the field of ``capture`` will hold, from its layout alone (the
        values are not read): what a run's plan sizes the run with. Default: None (known
        only once transformed)."""
        return None

    def frequency_count(self, n_bins: int) -> int:
        """How many frequencies the field of a capture of ``n_bins`` time bins holds, at
        most (the run's memory estimate, before the capture exists). Default: the positive
        bins of its DFT, ``n_bins // 2``; a transform that knows its count says it."""
        return max(1, int(n_bins) // 2)

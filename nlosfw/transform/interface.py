"""The phasor-transform interface: a transient capture in, a phasor field out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, TypeVar

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

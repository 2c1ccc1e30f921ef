"""The imager interface: a phasor field in, a reconstruction of the hidden volume out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, TypeVar

import numpy as np

from nlosfw.common.config import Configurable
from nlosfw.common.memory import MemoryEstimate, PlanShape
from nlosfw.common.progress import ProgressCallback
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True)
class ImagerConfig:
    """Options shared by every imager (none yet)."""


ImagerConfigT = TypeVar("ImagerConfigT", bound=ImagerConfig)


class Imager(Configurable[ImagerConfigT], ABC):
    """Propagates a :class:`PhasorField` into the hidden volume and images it."""

    config_class: ClassVar[type] = ImagerConfig
    #: True for imagers that image only fields on the wall's full regular grid, in the time
    #: domain (lct, fk, fbp): the pipeline gives them the ``raw`` source's samples on the
    #: full grid with zeros elsewhere, and does not warn about band aliasing for them. A
    #: declaration: the run's plan reads it (:class:`ImagerNeeds`), nothing else does.
    full_grid_only: ClassVar[bool] = False

    @classmethod
    def estimate_memory(cls, config: ImagerConfigT, shape: PlanShape,
                        planes: int) -> MemoryEstimate:
        """The memory one reconstruction with ``config`` holds beyond the field and the
        voxels and images the run counts itself, for a run of ``shape`` imaging ``planes``
        depth planes: its own work arrays (padded volumes, spectra, kernels). From the
        options and the sizes alone, nothing allocated or imported; a part the shape does
        not know yet (None) is bounded or left out. Default: nothing."""
        return MemoryEstimate()

    @abstractmethod
    def reconstruct(self, field: PhasorField, voxels: np.ndarray,
                    on_progress: ProgressCallback | None = None) -> Reconstruction:
        """Intensity at ``voxels``: a plane (Y, X, 3), planes (Z, Y, X, 3) or points (N, 3).

        ``on_progress(done, total)``, when given, is called each time a block of the work
        (a depth plane, a block of voxels) finishes, the last time with ``done == total``
        (:mod:`nlosfw.common.progress`; declare the ``progress`` capability). An imager
        without the keyword still works: the pipeline then shows no per-block progress.
        """


@dataclass(frozen=True)
class ImagerNeeds:
    """What an imager needs of the fields it images, as its class declares it:
    ``time_domain``, the field on the wall's full grid (the transient imagers), which the
    run decides the measured-capture band, the ``raw`` source's zero filling, the
    reference picture and the band-aliasing warning from."""

    time_domain: bool = False


#: The interface class of each plugin kind (by :class:`~nlosfw.plugins.PluginKind` value).

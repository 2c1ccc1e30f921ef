"""The field-model interface: a continuous F(x, y, f) -> P fitted to a discrete phasor field."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np
import numpy.typing as npt

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.config import Configurable, require, require_seed
from nlosfw.common.errors import DataError, FitError
from nlosfw.common.memory import MemoryEstimate, PlanShape
from nlosfw.transform.field import PhasorField


@dataclass(frozen=True)
class FieldModelConfig:
    """Options shared by every field model."""

    seed: int = 0
    """Seed of initialisation and batching: same seed and data, same model (on CPU)."""
    device: str = "auto"
    """Where to train: ``auto`` (a GPU when present), ``cpu``, or a backend device name."""

    def __post_init__(self) -> None:
        require_seed(self.seed, "seed")
        require(bool(self.device), "device", "must be auto, cpu or a device name")

    @property
    def uses_noise_variance(self) -> bool:
        """Whether the fit weighs samples by the training field's ``variance`` (the run then
        computes it, from a capture of photon counts); False unless a model says so. A
        declaration: the run's plan reads it (:class:`ModelNeeds`), nothing else does."""
        return False

    @property
    def uses_photon_counts(self) -> bool:
        """Whether the fit takes the training field's photon counts (``PhasorField.counts``:
        the run then carries them, from a capture of photon counts, with no frequency held
        out); False unless a model says so. A declaration: the run's plan reads it."""
        return False


@dataclass(frozen=True)
class ModelNeeds:
    """What a field model's fit needs from the run beyond the training field's values, as
    its config declares it: the field's Poisson ``noise_variance``, the ``photon_counts``
    it was transformed from. The run's plan reads the declarations once; the stages read
    these."""

    photon_counts: bool = False
    noise_variance: bool = False

    @property
    def counts(self) -> bool:
        """Whether the capture must hold photon counts (for either need)."""
        return self.photon_counts or self.noise_variance

    def __or__(self, other: ModelNeeds) -> ModelNeeds:
        return ModelNeeds(photon_counts=self.photon_counts or other.photon_counts,
                          noise_variance=self.noise_variance or other.noise_variance)


@dataclass(frozen=True)
class TrainingStep:
    """Progress of a fit, reported to ``on_step`` callbacks."""

    step: int
    total_steps: int
    loss: float
    val_loss: float | None = None
    seconds: float = 0.0


@dataclass(frozen=True)
class FitReport:
    """What happened during :meth:`FieldModel.fit`."""

    steps: int
    seconds: float
    final_loss: float
    best_val_loss: float | None = None
    stopped_early: bool = False
    history: list[dict[str, float]] = field(default_factory=list)
    fitted: dict[str, float] = field(default_factory=dict)
    """Numbers the fit estimated besides the model's parameters, by name (in metrics.json)."""


ModelConfigT = TypeVar("ModelConfigT", bound=FieldModelConfig)


class FieldModel(Configurable[ModelConfigT], ABC):
    """A continuous representation F(x, y, omega) -> P fitted to a discrete phasor field."""

    config_class: ClassVar[type] = FieldModelConfig

    @classmethod
    def check_config(cls, config: ModelConfigT) -> None:
        """Check what ``config`` names outside itself (a registered network, its options)
        before a run starts: a one-line ConfigError naming the option. Default: nothing."""

    @classmethod
    def estimate_memory(cls, config: ModelConfigT, shape: PlanShape) -> MemoryEstimate:
        """The memory a fit and prediction of this model with ``config`` hold beyond the
        fields the run counts itself (the training field, the predicted field), for a run
        of ``shape``: its own arrays, a backend's runtime, a network's training. From the
        options and the sizes alone, nothing allocated or imported; a part that depends on
        what the shape does not know yet (None) is bounded or left out. Default: nothing
        (a model that holds little beside its fields)."""
        return MemoryEstimate()

    @abstractmethod
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Fit to ``field``; ``validation`` (if given) drives early stopping."""

    @abstractmethod
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Complex field at wall points ``wall_xy`` (..., 2) and ``frequencies`` (F,).

        Returns shape (F, ...). Works after :meth:`fit` or :meth:`load` only.
        """

    @property
    @abstractmethod
    def n_parameters(self) -> int:
        """Number of trainable parameters (or stored values for non-neural models)."""

    @abstractmethod
    def save(self, path: str | Path) -> None:
        """Write weights, config and normalisation to one file."""

    @classmethod
    @abstractmethod
    def load(cls, path: str | Path) -> FieldModel:
        """Read a file written by :meth:`save` of the same model class."""

    def predict_field(self, wall_xyz: np.ndarray, frequencies: np.ndarray,
                      geometry: CaptureGeometry, weights: np.ndarray | None = None,
                      metadata: Mapping[str, Any] | None = None) -> PhasorField:
        """The model evaluated on a wall grid ``wall_xyz`` (Y, X, 3) as a :class:`PhasorField`."""
        wall_xyz = np.asarray(wall_xyz, dtype=float)
        values = self.predict(wall_xyz[..., :2], np.asarray(frequencies, dtype=float))
        return PhasorField(values=values, frequencies=frequencies, wall_xyz=wall_xyz,
                           geometry=geometry, weights=weights, metadata=dict(metadata or {}))


def check_training_field(field: PhasorField, who: str) -> None:
    """One-line errors for fields nothing can be fitted to."""
    if not isinstance(field, PhasorField):
        raise DataError(f"{who}: fit needs a PhasorField, got {type(field).__name__}")
    if field.values.size == 0:
        raise FitError(f"{who}: the field is empty (shape {field.values.shape})")
    if not np.any(field.values != 0):
        raise FitError(f"{who}: the field's values are all zero; nothing to fit")


def check_query(wall_xy: npt.ArrayLike, frequencies: npt.ArrayLike, who: str
                ) -> tuple[np.ndarray, np.ndarray]:
    """Validated (wall points (..., 2) float64, frequencies (F,) float64) for ``predict``."""
    xy = np.asarray(wall_xy, dtype=np.float64)
    f = np.atleast_1d(np.asarray(frequencies, dtype=np.float64))
    if xy.ndim < 1 or xy.shape[-1] != 2:
        raise DataError(f"{who}: wall_xy must have shape (..., 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise DataError(f"{who}: wall_xy contains NaN or inf")
    if f.ndim != 1:
        raise DataError(f"{who}: frequencies must be one-dimensional, got shape {f.shape}")
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise DataError(f"{who}: frequencies must be finite and > 0 (cycles per metre)")
    return xy, f

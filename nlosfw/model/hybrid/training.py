"""What the neural hidden volume's backend training loops keep: the history entries, the
step with the lowest validation error and the albedo's total variation
(:meth:`NeuralVolumeFieldModel.train`)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol, cast

import numpy as np


def albedo_total_variation(albedo: np.ndarray) -> float:
    """The total variation of an albedo (Z, Y, X) within each depth plane relative to its
    sum: (sum |a[z, y, x+1] - a[z, y, x]| + sum |a[z, y+1, x] - a[z, y, x]|) / sum a (0 for
    an albedo that is zero everywhere). The neural volume's ``albedo_tv`` term; each backend
    writes it in its own arrays, holding the sum constant within a step."""
    a = np.asarray(albedo, dtype=np.float64)
    total = float(np.sum(a))
    if not total > 0:
        return 0.0
    return float(np.sum(np.abs(np.diff(a, axis=2))) + np.sum(np.abs(np.diff(a, axis=1)))) \
        / total


def history_entry(step: int, loss: float, validation: float | None) -> dict[str, float]:
    """A fit-history entry of the backends' loops: the step, the training loss and, with
    validation points, their error (``val_loss``)."""
    entry: dict[str, float] = {"step": step, "loss": loss}
    if validation is not None:
        entry["val_loss"] = validation
    return entry


class _Summable(Protocol):
    """What :class:`BestStep` averages: a backend's array (numpy, torch, JAX)."""

    def __add__(self, other: _Summable, /) -> _Summable: ...

    def __truediv__(self, count: int, /) -> _Summable: ...


@dataclass
class BestStep:
    """The step with the lowest validation error so far (no validation: the latest) and its
    albedo (a backend array), for :meth:`NeuralVolumeFieldModel.train`'s loops; with
    ``window`` > 1, the mean of the albedos of the last ``window`` steps up to it."""

    patience: int
    window: int = 1
    step: int = 0
    error: float = float("inf")
    albedo: object = None
    recent: deque[_Summable] = field(default_factory=deque)

    def offer(self, step: int, error: float | None, albedo: object) -> None:
        """Keep ``albedo`` (the state before step ``step``'s update), or the mean of it and the
        ``window`` - 1 offered before it, if it is the best."""
        self.recent.append(cast(_Summable, albedo))
        if len(self.recent) > self.window:
            self.recent.popleft()
        if error is None or error < self.error:
            first, *rest = self.recent
            for other in rest:
                first = first + other
            kept = first / len(self.recent) if rest else albedo
            self.step, self.error, self.albedo = step, math.inf if error is None else error, \
                kept

    @property
    def validation(self) -> float | None:
        """The kept step's validation error (None: no validation)."""
        return self.error if math.isfinite(self.error) else None

    def stop(self, step: int) -> bool:
        """Whether ``patience`` steps passed without a better validation error."""
        return self.patience > 0 and math.isfinite(self.error) and \
            step - self.step >= self.patience

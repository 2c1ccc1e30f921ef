"""The stacked ensemble: physical field models weighed by their error at kept wall points
they did not see, and a residual network on their blend.

No one field model wins on every measured capture (``python -m nlosfw plugins
ensemble_torch``). Which does is decided here from the training field alone:

1. ``volume.validation_fraction`` of the kept wall points V (every frequency of each),
   drawn with ``seed``, are held out: exactly the points the neural volume holds out for its
   own early stopping (:func:`~nlosfw.model.physics.wall.validation_split` on the same
   grid, fraction and seed), so the volume is fitted once, on the whole field, and is the
   ``neural_volume_<backend>`` model a user would fit alone;
2. the members: the neural volume, and ``rsd_prior`` at each of ``tv_weights`` (a total
   variation of the albedo within each depth plane, the prior of the flat, sharp-edged
   targets of these captures; without it ``rsd_prior``'s sparse albedo images as speckle),
   fitted on the other kept points T;
3. the convex weights w (w >= 0, sum 1) minimising the members' squared error at V, over
   every training frequency (:func:`~nlosfw.model.hybrid.stacking.simplex_weights`): the
   blend B = sum_k w_k F_k;
4. with ``add_residual``, a residual network (``rsd_residual``'s, options ``residual``)
   fitted to the field minus B at T, scaled by the a in [0, 1] that best predicts V's
   remaining error: the prediction is B + a s r (s = 1 / (1 + residual_weight)). This is
   what ``rsd_residual`` adds to ``rsd_prior``, added to the best physics.

A member with weight 1 and no residual is predicted exactly (the neural volume: as fitted
alone). The error at V is the members' error against the noise-free field plus the same
noise for each (V's noise is independent of what they were fitted on), so the weights
follow the error at unseen points; the volume's is a little optimistic, since its early
stopping chose its step there. The fit reports each member's weight (``weight_<member>``),
error at V (``validation_db_<member>``, dB of the power there) and steps (``steps_<member>``,
its first fit's), the blend's error, and the residual's scale (``residual_scale``).

Cost: the neural volume's fit, one ``rsd_prior`` fit per TV weight and a small network.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import time
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import ClassVar

import numpy as np

from nlosfw.common.cores import available_cores
from nlosfw.common.errors import ConfigError, DataError, FitError
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.model.hybrid.beside import attempt, fit_beside
from nlosfw.model.hybrid.ensemble_config import VOLUME_LABEL, EnsembleConfig, prior_label
from nlosfw.model.hybrid.residual import RSDResidualFieldModel
from nlosfw.model.hybrid.stacking import (
    HeldOutPoints,
    held_out_points,
    simplex_weights,
    stacking_problem,
    subset_field,
)
from nlosfw.model.hybrid.volume import NeuralVolumeFieldModel
from nlosfw.model.interface import (
    FieldModel,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, stored_config, write_model_file
from nlosfw.model.neural.trainer import NeuralFieldModel
from nlosfw.model.physics.config import options_in_group
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

StepCallback = Callable[[TrainingStep], None] | None
#: A member weighed below this is dropped and the other weights scaled up to sum to 1:
#: its share is within what a few held-out points can tell apart, and a member kept costs a
#: fit on every kept point (and a clear choice is then exactly one member).
MIN_WEIGHT = 0.05
#: The residual network's name in saved files.
RESIDUAL_FILE = "residual_network"


class EnsembleFieldModel(FieldModel[EnsembleConfig]):
    """Members weighed by their error at held-out kept wall points, plus a residual (see
    the module docstring). A backend subclass sets ``backend`` and implements
    :meth:`residual_class` and :meth:`volume_class`."""

    config_class = EnsembleConfig
    family = "ensemble"
    backend: ClassVar[str] = ""
    """The backend of the networks (``torch``, ``jax``)."""

    def __init__(self, config: EnsembleConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._members: dict[str, FieldModel] = {}
        self._weights: dict[str, float] = {}
        self._residual: NeuralFieldModel | None = None
        self._residual_scale = 0.0        # a * s: the network's output times this is added

    @classmethod
    def model_name(cls) -> str:
        """The registered name, e.g. ``ensemble_torch`` (also the tag in saved files)."""
        return f"{cls.family}_{cls.backend}"

    @classmethod
    def residual_class(cls) -> type[RSDResidualFieldModel]:
        """``rsd_residual_<backend>``'s class (its network fits the residual)."""
        raise NotImplementedError(f"{cls.__name__} names no backend")

    @classmethod
    def volume_class(cls) -> type[NeuralVolumeFieldModel]:
        """``neural_volume_<backend>``'s class."""
        raise NotImplementedError(f"{cls.__name__} names no backend")

    @classmethod
    def check_config(cls, config: EnsembleConfig) -> None:
        """The members' own checks (errors name ``model.residual.*``, ``model.volume.*``)."""
        if config.add_residual:
            with options_in_group("residual"):
                cls.residual_class().check_config(config.residual_config())
        if config.neural_volume:
            with options_in_group("volume"):
                cls.volume_class().check_config(config.volume_config())

    @classmethod
    def estimate_memory(cls, config: EnsembleConfig, shape: PlanShape) -> MemoryEstimate:
        """The members' estimates together (each part's why names its member; a runtime
        they share counts once), and the members' fields on the wall grid that weigh them
        (one per member, the blend and the residual's, every training frequency)."""
        estimate = MemoryEstimate()
        if config.neural_volume:
            estimate += _member_part(VOLUME_LABEL, cls.volume_class().estimate_memory(
                config.volume_config(), shape))
        for weight in config.tv_weights:
            estimate += _member_part(prior_label(weight), RSDPriorFieldModel.estimate_memory(
                config.prior_member_config(weight), shape))
        if config.add_residual:
            estimate += _member_part("residual", cls.residual_class().estimate_memory(
                config.residual_config(), shape))
        if config.member_count > 1 or config.add_residual:
            ny, nx = shape.square_grid
            fields = config.member_count + 1 + int(config.add_residual)
            estimate += MemoryEstimate((MemoryPart(
                "the members' fields", f"{fields} fields of {shape.training_frequencies} "
                f"frequencies × {ny} × {nx} wall points", 16.0 * fields
                * shape.training_frequencies * ny * nx),))
        return estimate

    @property
    def member_weights(self) -> dict[str, float]:
        """Each member's weight after :meth:`fit` or :meth:`load`, by label
        (``rsd_prior_tv0.1``, ``neural_volume``)."""
        self._fitted()
        return {label: self._weights.get(label, 0.0) for label in self._labels()}

    @property
    def residual_scale(self) -> float:
        """The scale a of the residual network's penalised output (0: none added)."""
        self._fitted()
        return self._residual_scale * (1.0 + self.config.residual.residual_weight)

    def _labels(self) -> list[str]:
        cfg = self.config
        return ([VOLUME_LABEL] if cfg.neural_volume else []) + \
            [prior_label(w) for w in cfg.tv_weights]

    # ------------------------------------------------------------------ fit
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: StepCallback = None) -> FitReport:
        """Fit the members, weigh them and the residual (see the module docstring;
        ``validation`` is unused: the held-out points are the field's own)."""
        start = time.perf_counter()
        who = self.model_name()
        check_training_field(field, who)
        cfg = self.config
        if cfg.member_count == 1 and not cfg.add_residual:
            label = self._labels()[0]
            model, report = self._fit_member(label, field, on_step)
            self._members, self._weights = {label: model}, {label: 1.0}
            self._residual, self._residual_scale = None, 0.0
            return dataclasses.replace(report, fitted={**report.fitted, f"weight_{label}": 1.0},
                                       seconds=time.perf_counter() - start)
        held = held_out_points(field, cfg.volume.validation_fraction, cfg.seed, who)
        measured = held.measured(field)
        power = float(np.sum(np.abs(measured) ** 2))
        if not power > 0:
            raise FitError(f"{who}: the field is zero at the {held.count} held-out kept wall "
                           "points; they cannot weigh the members")
        trained = subset_field(field, ~held.validation)
        fitted, reports = self._fit_members(field, trained, on_step)
        labels = list(fitted)
        grids = {label: held.on_grid(fitted[label], field.frequencies) for label in labels}
        at_v = np.stack([grids[label][:, held.canonical] for label in labels])
        gram, target, total = stacking_problem(at_v, measured)
        w = simplex_weights(gram, target)
        kept = w >= MIN_WEIGHT
        kept[int(np.argmax(w))] = True
        w = np.where(kept, w, 0.0) / float(np.sum(w[kept]))
        weights = {label: float(v) for label, v in zip(labels, w, strict=True) if v > 0}
        blend = np.zeros_like(grids[labels[0]], dtype=np.complex128)
        for label, weight in weights.items():
            blend += weight * grids[label]
        blend_error = float(np.sum(np.abs(blend[:, held.canonical] - measured) ** 2)) / power
        info: dict[str, float] = {"validation_points": float(held.count),
                                  "validation_db_blend": _db(blend_error)}
        for label, row in zip(labels, at_v, strict=True):
            info[f"weight_{label}"] = weights.get(label, 0.0)
            info[f"steps_{label}"] = float(reports[label].steps)
            info[f"validation_db_{label}"] = _db(
                float(np.sum(np.abs(row - measured) ** 2)) / power)
        scale, error = 0.0, blend_error
        if cfg.add_residual:
            scale, error, reports["residual"], found = self._scale_residual(field, held,
                                                                            blend, on_step)
            info.update(found)
        self._members = self._refitted(field, fitted, weights, reports, on_step)
        self._weights = weights
        self._residual, self._residual_scale = None, 0.0
        if scale > 0:
            self._fit_final_residual(field, held, scale, on_step)
        info["validation_db"] = _db(error)
        log.info("%s: weights %s, residual scale %.3g, held-out error %.2f dB (%d points)",
                 who, {k: round(v, 3) for k, v in weights.items()},
                 info.get("residual_scale", 0.0), _db(error), held.count)
        for name, report in reports.items():
            info.update({f"{name}_{k}": v for k, v in report.fitted.items()})
        history = [{"stage": float(i), **h} for i, report in enumerate(reports.values())
                   for h in report.history]
        return FitReport(steps=sum(r.steps for r in reports.values()),
                         seconds=time.perf_counter() - start, final_loss=error,
                         best_val_loss=error, history=history, fitted=info)

    def _fit_member(self, label: str, field: PhasorField, on_step: StepCallback = None,
                    workers: int | None = None) -> tuple[FieldModel, FitReport]:
        """Member ``label`` fitted to ``field`` (an ``rsd_prior`` one on ``workers``
        threads, if given)."""
        cfg = self.config
        model: FieldModel
        if label == VOLUME_LABEL:
            model = self.volume_class()(cfg.volume_config())
            with options_in_group("volume"):
                return model, model.fit(field, on_step=on_step)
        weight = next(w for w in cfg.tv_weights if prior_label(w) == label)
        model = RSDPriorFieldModel(cfg.prior_member_config(weight, workers))
        with options_in_group("prior"):
            return model, model.fit(field, on_step=on_step)

    def _fit_members(self, field: PhasorField, trained: PhasorField, on_step: StepCallback
                     ) -> tuple[dict[str, FieldModel], dict[str, FitReport]]:
        """Each member: the volume on the whole field (it holds out the held-out points
        itself), ``rsd_prior`` on the rest. A member that cannot fit the field (a FitError:
        e.g. no non-negative albedo correlates with it) is left out with a warning; if
        every one is, the first error stands."""
        labels = self._labels()
        fits = {label: partial(self._fit_member, label,
                               field if label == VOLUME_LABEL else trained)
                for label in labels}
        outcomes: dict[str, tuple[FieldModel, FitReport] | FitError]
        if self.config.concurrent and VOLUME_LABEL in labels and len(labels) > 1:
            # the volume in a second thread, the priors here on the cores it leaves
            workers = self.config.workers_beside_volume
            # once the priors end, the volume takes their cores (0: every core already)
            own = self.config.volume.threads
            widen = None if own == 0 else partial(self.volume_class().use_threads,
                                                  min(available_cores(), own + workers))
            priors = {label: partial(self._fit_member, label, trained, workers=workers)
                      for label in labels if label != VOLUME_LABEL}
            outcomes = fit_beside((VOLUME_LABEL, fits[VOLUME_LABEL]), priors, on_step,
                                  name="nlosfw-neural-volume", on_alone=widen)
        else:
            outcomes = {label: attempt(fit, on_step) for label, fit in fits.items()}
        fitted: dict[str, FieldModel] = {}
        reports: dict[str, FitReport] = {}
        failures: list[FitError] = []
        for label in labels:                       # in the members' order, either way
            outcome = outcomes[label]
            if isinstance(outcome, FitError):
                failures.append(outcome)
                log.warning("%s: member %s left out: %s", self.model_name(), label, outcome)
            else:
                fitted[label], reports[label] = outcome
        if not fitted:
            raise failures[0]
        return fitted, reports

    def _refitted(self, field: PhasorField, fitted: Mapping[str, FieldModel],
                  weights: Mapping[str, float], reports: dict[str, FitReport],
                  on_step: StepCallback) -> dict[str, FieldModel]:
        """The members with a weight, the ``rsd_prior`` ones fitted again on every kept point
        (the volume already was)."""
        final = {}
        for label in weights:
            if label == VOLUME_LABEL:
                final[label] = fitted[label]
            else:
                final[label], reports[label] = self._fit_member(label, field, on_step)
        return final

    def _scale_residual(self, field: PhasorField, held: HeldOutPoints, blend: np.ndarray,
                        on_step: StepCallback) -> tuple[float, float, FitReport,
                                                        dict[str, float]]:
        """The residual network fitted to the field minus the blend (F, ny, nx) at the kept
        points not held out, and the scale a in [0, 1] of its penalised output that best
        predicts the blend's error at the held-out ones: (a, the held-out error with it,
        relative; the network's fit report; what it found)."""
        residual_model = self.residual_class()(self.config.residual_config())
        left = (field.values - held.in_field_layout(blend)).astype(field.values.dtype)
        residual = subset_field(field.replace(values=left, variance=None, counts=None),
                                ~held.validation)
        with options_in_group("residual"):
            network, report = residual_model.fit_network(residual, on_step=on_step)
        measured = held.measured(field)
        r = residual_model.shrink * held.on_grid(network, field.frequencies)[:, held.canonical]
        gap = measured - blend[:, held.canonical]
        norm = float(np.sum(np.abs(r) ** 2))
        scale = min(max(float(np.real(np.vdot(r, gap))) / norm, 0.0), 1.0) if norm > 0 else 0.0
        power = float(np.sum(np.abs(measured) ** 2))
        found = {"residual_scale": scale, "validation_db_unscaled_residual": _db(
            float(np.sum(np.abs(gap - r) ** 2)) / power)}
        return scale, float(np.sum(np.abs(gap - scale * r) ** 2)) / power, report, found

    def _fit_final_residual(self, field: PhasorField, held: HeldOutPoints, scale: float,
                            on_step: StepCallback) -> None:
        """The residual network fitted again, to the field minus the final members' blend at
        every kept point, with the scale the held-out points chose."""
        residual_model = self.residual_class()(self.config.residual_config())
        blend = np.zeros((field.n_frequencies, *held.samples.layout.shape), np.complex128)
        for label, model in self._members.items():
            blend += self._weights[label] * held.on_grid(model, field.frequencies)
        left = (field.values - held.in_field_layout(blend)).astype(field.values.dtype)
        with options_in_group("residual"):
            network, _ = residual_model.fit_network(
                field.replace(values=left, variance=None, counts=None), on_step=on_step)
        self._residual, self._residual_scale = network, scale * residual_model.shrink

    # ------------------------------------------------------------------ predict
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """sum_k w_k F_k + a s r at wall points (..., 2) and frequencies (F,) -> complex
        (F, ...) (exactly the member's field when one weight is 1 and a is 0)."""
        xy, f = check_query(wall_xy, frequencies, self.model_name())
        total: np.ndarray | None = None
        for label, model in self._fitted().items():
            weight = self._weights[label]
            part = model.predict(xy, f).astype(np.complex128)
            if weight != 1.0:
                part = weight * part
            total = part if total is None else total + part
        if total is None:
            raise FitError(f"{self.model_name()}: no member has a weight")
        if self._residual is not None:
            total = total + self._residual_scale * self._residual.predict(xy, f)
        return total

    def _fitted(self) -> dict[str, FieldModel]:
        if not self._members:
            raise FitError(f"{self.model_name()}: call fit() or load() before predict() or "
                           "save()")
        return self._members

    @property
    def members(self) -> dict[str, FieldModel]:
        """The members with a weight, by label (fitted)."""
        return dict(self._fitted())

    @property
    def n_parameters(self) -> int:
        """The weighed members' parameters and the residual network's."""
        if not self._members:
            raise FitError(f"{self.model_name()}: the number of parameters is known after "
                           "fit or load")
        network = 0 if self._residual is None else self._residual.n_parameters
        return sum(model.n_parameters for model in self._members.values()) + network

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        """One file: the config, the weights, the residual's scale and each weighed
        member's (and the residual network's) own file as bytes."""
        parts: dict[str, FieldModel] = dict(self._fitted())
        if self._residual is not None:
            parts[RESIDUAL_FILE] = self._residual
        arrays = {}
        with tempfile.TemporaryDirectory() as tmp:
            for label, model in parts.items():
                part_path = Path(tmp) / "part"
                model.save(part_path)
                arrays[label] = np.frombuffer(part_path.read_bytes(), dtype=np.uint8)
        write_model_file(path, self.model_name(), self.config, arrays,
                         {"backend": self.backend, "family": self.family,
                          "weights": dict(self._weights),
                          "residual_scale": self._residual_scale})

    @classmethod
    def load(cls, path: str | Path) -> EnsembleFieldModel:
        header, arrays = read_model_file(path, cls.model_name())
        try:
            model = cls(stored_config(cls.config_class, header))
            weights = {str(label): float(w) for label, w in header["weights"].items()}
            scale = float(header["residual_scale"])
            labels = [*weights, *([RESIDUAL_FILE] if scale != 0 else [])]
            stored = {label: np.asarray(arrays[label], dtype=np.uint8).tobytes()
                      for label in labels}
        except (KeyError, TypeError, ValueError, AttributeError, ConfigError) as err:
            raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                            f"({type(err).__name__})") from None
        known = set(model._labels())
        if not weights or not set(weights) <= known or not all(
                math.isfinite(w) and w > 0 for w in weights.values()) or \
                not math.isfinite(scale):
            raise DataError(f"model file {path}: invalid {cls.model_name()} file (weights "
                            f"{header['weights']}, residual scale {header['residual_scale']})")
        parts: dict[str, FieldModel] = {}
        with tempfile.TemporaryDirectory() as tmp:
            for label, data in stored.items():
                part_path = Path(tmp) / "part"
                part_path.write_bytes(data)
                try:
                    parts[label] = model._part_class(label).load(part_path)
                except DataError as err:
                    raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                                    f"({label}: {err})") from None
        network = parts.pop(RESIDUAL_FILE, None)
        if network is not None and not isinstance(network, NeuralFieldModel):
            raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                            "(its residual is no network)")
        model._members, model._weights = parts, weights
        model._residual, model._residual_scale = network, scale
        return model

    def _part_class(self, label: str) -> type[FieldModel]:
        if label == VOLUME_LABEL:
            return self.volume_class()
        if label == RESIDUAL_FILE:
            return self.residual_class().network_class(self.config.residual.network)
        return RSDPriorFieldModel


def _member_part(label: str, estimate: MemoryEstimate) -> MemoryEstimate:
    """``estimate`` with each part's why naming the member (a shared runtime as it is)."""
    return MemoryEstimate(tuple(part if part.once else dataclasses.replace(
        part, why=f"member {label}: {part.why}") for part in estimate.parts))


def _db(ratio: float) -> float:
    """10 log10 of an error ratio, in decibels (the ratio floored at 1e-30: an exact fit stays
    a number)."""
    return 10.0 * math.log10(max(ratio, 1e-30))

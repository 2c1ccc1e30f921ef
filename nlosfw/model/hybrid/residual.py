"""The physics field with a neural residual: ``rsd_prior``'s field plus a small network.

The fit runs in two stages on the kept wall samples P (every training frequency):

1. the physics: :class:`~nlosfw.model.physics.prior.RSDPriorFieldModel` (a non-negative
   hidden albedo fitted by FISTA, propagated to the wall by RSD) with this config's group
   ``prior`` (``rsd_prior``'s options); its field at the kept samples is Q;
2. the residual: a registered network (``network``, any of the ``register_networks``
   API, on the backend of the subclass) r(x, y, f) minimising

       sum |r - (P - Q)|^2 + residual_weight * sum |r|^2      (over the kept samples)

   The penalty keeps the residual small. Its minimiser over any network whose output layer
   is linear (every registered one: scaling that layer scales the output) is the
   unpenalised least-squares fit r_0 scaled by 1 / (1 + residual_weight) (pointwise,
   |r - R|^2 + w |r|^2 = (1 + w) |r - R / (1 + w)|^2 + const). So the network is trained by
   the shared trainer on P - Q (normalised, well conditioned at any weight) and its output
   is scaled: the prediction is Q + r_0 / (1 + residual_weight). A very large weight gives
   ``rsd_prior``'s field; 0 lets the network fit everything the physics misses. The
   network's training length is chosen on held-out whole wall points
   (``network_validation_fraction``, early stopping with ``network_patience``), since
   predicting unseen wall points is its job.

The backend is the subclass's (``nlosfw-torch``: ``rsd_residual_torch``, ``nlosfw-jax``:
``rsd_residual_jax``): it names the backend and finds the network class in the registry.
Both stages are stored in one model file (each stage's own file, embedded as bytes).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from nlosfw.common.config import require, require_threads
from nlosfw.common.errors import ConfigError, DataError, FitError
from nlosfw.common.memory import MemoryEstimate, PlanShape
from nlosfw.model.interface import (
    FieldModel,
    FieldModelConfig,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, stored_config, write_model_file
from nlosfw.model.neural.config import FieldMode, NeuralFieldConfig, wrapped_network_config
from nlosfw.model.neural.memory import field_shape, network_memory
from nlosfw.model.neural.trainer import NeuralFieldModel
from nlosfw.model.physics.config import (
    FLAT_NAMES,
    PriorOptions,
    RSDPriorConfig,
    moved_into,
    options_in_group,
    prior_config,
)
from nlosfw.model.physics.likelihood import Likelihood
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.transform.field import PhasorField

#: The stored stage files' names inside the model file.
_STAGES = ("prior_file", "network_file")


@dataclass(frozen=True)
class RSDResidualConfig(FieldModelConfig):
    """Options of the physics field with a neural residual: the residual network's and,
    in the group ``prior``, ``rsd_prior``'s (the physics stage; ``seed`` is both stages',
    ``device`` the network's: ``auto`` trains it on a GPU when the backend sees one)."""

    #: ``rsd_prior``'s options were this config's own, flat, before they became ``prior``.
    renamed_options: ClassVar[Mapping[str, str]] = moved_into("prior", FLAT_NAMES)

    network: str = "siren"
    """The residual network: a name registered through ``register_networks`` for this
    model's backend (siren, fourier, hashgrid, ...)."""
    residual_weight: float = 1.0
    """Penalty weight w on the residual's squared size over the kept samples, relative to
    the data term: the residual is the unpenalised fit scaled by 1 / (1 + w) (0: none; very
    large: rsd_prior's field)."""
    network_hidden: tuple[int, ...] = (32, 32)
    """Widths of the residual network's hidden layers (small: it fits what the physics
    misses, not the field)."""
    network_steps: int = 1000
    """Adam steps of the residual network."""
    network_lr: float = 1e-3
    """Peak learning rate of the residual network."""
    network_batch_size: int = 8192
    """Training samples per step of the residual network (0: full batch)."""
    network_validation_fraction: float = 0.1
    """Fraction of the kept wall points (every frequency of each) held out to choose the
    residual network's training length (0: none; a validation field, when the run gives
    one, replaces it). Whole wall points, not random samples: what the residual must do is
    predict wall points it has not seen."""
    network_patience: int = 4
    """Validation evaluations without improvement before the network stops (0: never; the
    weights of the best evaluation are kept)."""
    network_threads: int = 1
    """CPU threads of the residual network's training (0: the backend's default)."""
    prior: PriorOptions = dataclasses.field(default_factory=PriorOptions)
    """The physics stage: ``rsd_prior``'s options (``model.prior.iterations``,
    ``model.prior.depth.range``, ...)."""

    @property
    def uses_noise_variance(self) -> bool:
        """With the prior's ``likelihood: poisson`` the fit needs the field's variance."""
        return self.prior.likelihood == Likelihood.poisson

    @property
    def uses_photon_counts(self) -> bool:
        """With the prior's ``likelihood: poisson_counts`` the fit needs the photon counts."""
        return self.prior.likelihood == Likelihood.poisson_counts

    def __post_init__(self) -> None:
        super().__post_init__()
        require(bool(self.network), "network", "must name a registered network, e.g. siren")
        require(self.residual_weight >= 0 and np.isfinite(self.residual_weight),
                "residual_weight", f"must be finite and >= 0, got {self.residual_weight}")
        require(len(self.network_hidden) >= 1 and all(h >= 1 for h in self.network_hidden),
                "network_hidden", f"must be one or more widths >= 1, got "
                f"{list(self.network_hidden)}")
        require(self.network_steps >= 1, "network_steps",
                f"must be >= 1, got {self.network_steps}")
        require(self.network_lr > 0 and np.isfinite(self.network_lr), "network_lr",
                f"must be > 0 and finite, got {self.network_lr}")
        require(self.network_batch_size >= 0, "network_batch_size",
                f"must be >= 0 (0: full batch), got {self.network_batch_size}")
        require(0 <= self.network_validation_fraction < 1, "network_validation_fraction",
                f"must be in [0, 1), got {self.network_validation_fraction}")
        require(self.network_patience >= 0, "network_patience",
                f"must be >= 0, got {self.network_patience}")
        require_threads(self.network_threads, "network_threads", 0, "the backend's default")

    def prior_config(self) -> RSDPriorConfig:
        """The physics stage's config: the group ``prior`` with this config's ``seed`` and
        ``device``."""
        return prior_config(self.prior, self.seed, self.device)

    def network_options(self) -> dict[str, object]:
        """The residual network's options (its config class fills in the rest)."""
        return {"seed": self.seed, "device": self.device, "hidden": list(self.network_hidden),
                "steps": self.network_steps, "lr": self.network_lr,
                "batch_size": self.network_batch_size,
                "validation_fraction": 0.0, "patience": self.network_patience,
                "eval_every": max(1, min(50, self.network_steps // 10)),
                "threads": self.network_threads}


#: The residual network's options this model sets from its own, by the network's name.
_NETWORK_NAMES = {"hidden": "network_hidden", "steps": "network_steps", "lr": "network_lr",
                  "batch_size": "network_batch_size", "patience": "network_patience",
                  "threads": "network_threads", "seed": "seed", "device": "device"}


def _network_config(network: type[NeuralFieldModel], config: RSDResidualConfig
                    ) -> NeuralFieldConfig:
    """The residual network's config (errors name this model's options)."""
    built: NeuralFieldConfig = wrapped_network_config(
        network.config_class, config.network_options(), _NETWORK_NAMES)
    return built


class RSDResidualFieldModel(FieldModel[RSDResidualConfig]):
    """``rsd_prior``'s field plus a penalised neural residual (see the module docstring).

    A backend subclass sets ``backend`` and implements :meth:`network_class`."""

    config_class = RSDResidualConfig
    family = "rsd_residual"
    backend: ClassVar[str] = ""
    """The backend of the residual network (``torch``, ``jax``)."""

    def __init__(self, config: RSDResidualConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._prior: RSDPriorFieldModel | None = None
        self._network: NeuralFieldModel | None = None

    @classmethod
    def model_name(cls) -> str:
        """The registered name, e.g. ``rsd_residual_torch`` (also the tag in saved files)."""
        return f"{cls.family}_{cls.backend}"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The field-model class of network ``name`` on this backend (the subclass finds it
        in the plugin registry)."""
        raise NotImplementedError(f"{cls.__name__} names no backend")

    @classmethod
    def check_config(cls, config: RSDResidualConfig) -> None:
        """The network must be registered for this backend (``model.network``), take this
        model's network options and the device (errors name ``model.network_lr``, ...)."""
        network = cls.network_class(config.network)
        network.check_config(_network_config(network, config))

    @classmethod
    def estimate_memory(cls, config: RSDResidualConfig, shape: PlanShape) -> MemoryEstimate:
        """The residual network's training on the field (``rsd_prior``'s own arrays are
        not counted: as for ``rsd_prior`` alone, they are small beside the fields)."""
        net_config = _network_config(cls.network_class(config.network), config)
        return network_memory(net_config, cls.backend,
                              field_shape(shape, FieldMode(net_config.mode)), shape.samples)

    def _network_model(self) -> NeuralFieldModel:
        network = self.network_class(self.config.network)
        model = network(_network_config(network, self.config))
        model.lr_option = f"model.{_NETWORK_NAMES['lr']}"
        return model

    # ------------------------------------------------------------------ fit
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Fit rsd_prior to ``field``, then the network to what it leaves (``validation``,
        if given, drives the network's early stopping)."""
        start = time.perf_counter()
        check_training_field(field, self.model_name())
        self._network_model()                   # a bad network name fails before the fit
        prior = RSDPriorFieldModel(self.config.prior_config())
        with options_in_group("prior"):
            prior_report = prior.fit(field)
        residual = _residual(prior, field)
        val_residual = None if validation is None else _residual(prior, validation)
        network, report = self.fit_network(residual, val_residual, on_step)
        self._prior, self._network = prior, network
        history = [{"stage": 0.0, **h} for h in prior_report.history]
        history += [{"stage": 1.0, **h} for h in report.history]
        return FitReport(steps=prior_report.steps + report.steps,
                         seconds=time.perf_counter() - start, final_loss=report.final_loss,
                         best_val_loss=report.best_val_loss,
                         stopped_early=report.stopped_early, history=history,
                         fitted=prior_report.fitted)

    def fit_network(self, residual: PhasorField, validation: PhasorField | None = None,
                    on_step: Callable[[TrainingStep], None] | None = None
                    ) -> tuple[NeuralFieldModel, FitReport]:
        """The second stage alone: a new network fitted to ``residual`` (what a physics
        stage leaves of a field; ``validation``, if given, drives its early stopping, else
        ``network_validation_fraction`` of its wall points are held out). Its output times
        :attr:`shrink` is the penalised residual. This model keeps nothing of it."""
        who = self.model_name()
        network = self._network_model()
        if not np.any(residual.values != 0):
            raise FitError(f"{who}: rsd_prior fits the field exactly; nothing is left for "
                           "the residual network (use model=rsd_prior)")
        if validation is None and self.config.network_validation_fraction > 0:
            residual, validation = _hold_out_points(
                residual, self.config.network_validation_fraction, self.config.seed)
        return network, network.fit(residual, validation, on_step)

    @property
    def shrink(self) -> float:
        """The factor 1 / (1 + residual_weight) on the network's output."""
        return 1.0 / (1.0 + self.config.residual_weight)

    # ------------------------------------------------------------------ predict
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """rsd_prior's field plus the scaled residual at wall points (..., 2) and
        frequencies (F,) -> complex (F, ...)."""
        xy, f = check_query(wall_xy, frequencies, self.model_name())
        prior, network = self._stages()
        physics = prior.predict(xy, f)
        return physics + self.shrink * network.predict(xy, f).astype(np.complex128)

    def physics(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """The physics stage's field alone (rsd_prior's prediction)."""
        xy, f = check_query(wall_xy, frequencies, self.model_name())
        return self._stages()[0].predict(xy, f)

    def _stages(self) -> tuple[RSDPriorFieldModel, NeuralFieldModel]:
        if self._prior is None or self._network is None:
            raise FitError(f"{self.model_name()}: call fit() or load() before predict() or "
                           "save()")
        return self._prior, self._network

    @property
    def n_parameters(self) -> int:
        """Voxels of the albedo plus the network's trainable parameters."""
        if self._prior is None or self._network is None:
            raise FitError(f"{self.model_name()}: the number of parameters is known after fit "
                           "or load")
        return self._prior.n_parameters + self._network.n_parameters

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        """One file: the config and both stages' own files, embedded as bytes."""
        stages: tuple[FieldModel, FieldModel] = self._stages()
        arrays = {}
        with tempfile.TemporaryDirectory() as tmp:
            for name, stage in zip(_STAGES, stages, strict=True):
                stage_path = Path(tmp) / name
                stage.save(stage_path)
                arrays[name] = np.frombuffer(stage_path.read_bytes(), dtype=np.uint8)
        write_model_file(path, self.model_name(), self.config, arrays,
                         {"backend": self.backend, "family": self.family})

    @classmethod
    def load(cls, path: str | Path) -> RSDResidualFieldModel:
        header, arrays = read_model_file(path, cls.model_name())
        try:
            model = cls(stored_config(cls.config_class, header))
            stored = [np.asarray(arrays[name], dtype=np.uint8).tobytes() for name in _STAGES]
        except (KeyError, TypeError, ValueError, ConfigError) as err:
            raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                            f"({type(err).__name__})") from None
        network_class = cls.network_class(model.config.network)
        with tempfile.TemporaryDirectory() as tmp:
            paths = [Path(tmp) / name for name in _STAGES]
            for stage_path, data in zip(paths, stored, strict=True):
                stage_path.write_bytes(data)
            try:
                prior = RSDPriorFieldModel.load(paths[0])
                network = network_class.load(paths[1])
            except DataError as err:
                raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                                f"(a stage: {err})") from None
        model._prior, model._network = prior, network
        return model


def _residual(prior: RSDPriorFieldModel, field: PhasorField) -> PhasorField:
    """``field`` minus the physics' field at its samples."""
    physics = prior.predict(field.wall_xyz[..., :2], field.frequencies)
    return field.replace(values=(field.values - physics).astype(field.values.dtype))


def _hold_out_points(field: PhasorField, fraction: float, seed: int
                     ) -> tuple[PhasorField, PhasorField | None]:
    """(training, validation): ``fraction`` of ``field``'s wall points, drawn by ``seed``,
    with every frequency, as a (F, 1, N) validation field (without the photon counts,
    which only the physics stage takes); no validation when fewer than 10 points would
    remain to train on."""
    n_f, n_y, n_x = field.values.shape
    n = n_y * n_x
    n_val = max(1, round(fraction * n))
    if n - n_val < 10:
        return field, None
    order = np.random.default_rng([seed, 0x76616C]).permutation(n)   # "val" stream
    values = field.values.reshape(n_f, 1, n)
    wall = field.wall_xyz.reshape(1, n, 3)
    var = None if field.variance is None else field.variance.reshape(n_f, 1, n)
    val, train = np.sort(order[:n_val]), np.sort(order[n_val:])
    return (field.replace(values=values[:, :, train], wall_xyz=wall[:, train], counts=None,
                          variance=None if var is None else var[:, :, train]),
            field.replace(values=values[:, :, val], wall_xyz=wall[:, val], counts=None,
                          variance=None if var is None else var[:, :, val]))

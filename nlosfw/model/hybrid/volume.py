"""The neural hidden volume: a coordinate network's non-negative albedo, propagated by RSD.

Like ``rsd_prior`` the field is explained by a hidden scene on voxel planes parallel to
the wall (the same lattice, depth planes, frequencies, device legs and normalisation, set up
as :class:`~nlosfw.model.physics.prior.RSDPriorFieldModel` does with the options of the
group ``prior``, its quick coarse fit finding the depth planes when ``prior.depth.range``
is not given), but the albedo is not
a free array: it is a registered network (``network``, any of the ``register_networks``
API, on the subclass's backend) evaluated at the voxel centres,

    a_v = s / mean(n) * softplus(net(x_v, y_v, z_v) + c)

with inputs scaled into [-0.9, 0.9] per axis, n_v = ||A e_v|| the operator's column
norms, s = max_v Re(A^H P)_v / n_v (the size, in units of n_v a_v, of a one-voxel fit),
and c such that an output of 0 gives ``albedo_start`` of it: a faint, nearly uniform
start. (Weighting each voxel by s / n_v instead, as ``rsd_prior``'s normalised variables
do, lit the weakly coupled lattice corners, where the uniform gain found the bright voxel
of the tests' sparse scene.) The network is trained by Adam on the kept
wall samples (every training frequency, full batch) by least squares,

    min  sum_f ||A_f a - P_f||^2 / sum_f ||P_f||^2  +  albedo_tv / N  TV(a) / sum(a),

over the N kept wall points not held out, with the operator A written once per backend
(torch, JAX: differentiable, native FFTs) from the numpy kernel spectra and laser legs of
:class:`~nlosfw.model.physics.operator.SceneOperator` (:func:`plane_stack`). The network's
smoothness is the prior, and with ``albedo_tv`` the albedo's total variation within each
depth plane relative to its sum (:func:`~nlosfw.model.hybrid.albedo_total_variation`; the
sum held constant within a step, so the term sharpens edges without dimming the volume),
its weight rising by at most ``albedo_tv_rise`` a step.
The fitted albedo predicts the field anywhere ``rsd_prior`` can (through
:meth:`RSDPriorFieldModel.from_albedo`).

A random scan trains like ``rsd_prior``'s: on the grid its points came from, the points not
kept weighing nothing in the loss, the validation points drawn from the kept ones.

The backend is the subclass's (``nlosfw-torch``: ``neural_volume_torch``, ``nlosfw-jax``:
``neural_volume_jax``): it finds the network class and implements :meth:`train`.

Cost: every step propagates the whole volume at every training frequency. The network
learns the scene first and the noise of the kept points later: ``validation_fraction`` of
the kept wall points are left out of the loss and the step with the lowest error there is
kept (``patience`` ends the training). Its fit times and held-out errors, with and without
that validation: ``studies/sparse_scans_measured/README.md``.
"""

from __future__ import annotations

import logging
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np

from nlosfw.common.errors import ConfigError, DataError, FitError
from nlosfw.common.files import format_bytes
from nlosfw.common.memory import MemoryEstimate, PlanShape, available_memory
from nlosfw.image.fft import Precision
from nlosfw.image.rsd_kernel import check_geometry
from nlosfw.model.hybrid.stack import PlaneStack, plane_stack, stack_bytes
from nlosfw.model.hybrid.volume_config import VOLUME_NAMES, NeuralVolumeConfig
from nlosfw.model.hybrid.volume_memory import volume_memory
from nlosfw.model.interface import (
    FieldModel,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, stored_config, write_model_file
from nlosfw.model.neural.config import (
    FieldMode,
    FieldShape,
    NeuralFieldConfig,
    wrapped_network_config,
)
from nlosfw.model.neural.steps import learning_rate
from nlosfw.model.neural.trainer import NeuralFieldModel
from nlosfw.model.physics.config import RSDPriorConfig, options_in_group
from nlosfw.model.physics.frequencies import fitted_frequencies
from nlosfw.model.physics.operator import OperatorOptions, SceneOperator, VoxelLattice
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.model.physics.wall import training_values, validation_split
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

#: Inputs of the network are scaled into [-MARGIN, MARGIN] per axis.
MARGIN = 0.9


@dataclass(frozen=True, eq=False)
class VolumeProblem:
    """What a backend trains on: the operator's constants, the normalised kept samples
    ``data`` (F, ny, nx) (canonical order), the network's inputs ``coords`` (V, 3) at the
    voxel centres (V = Z * Y * X, C order), ``gain`` = s / mean(n) (Z, Y, X) and ``shift`` = c
    (the albedo is gain * softplus(out + shift)), the network to build, which wall
    points (ny, nx) the loss uses (``train``, 1 or 0) and which choose the kept step
    (``validation``; None: no validation, or its points are all zero: the last step is
    kept), and the weight of the albedo's total variation in the loss (``tv_weight``:
    ``albedo_tv`` over the number of points the loss uses, rising by at most ``tv_rise``
    a step: :meth:`tv_weight_at`)."""

    stack: PlaneStack
    data: np.ndarray
    coords: np.ndarray
    gain: np.ndarray
    shift: float
    network: type[NeuralFieldModel]
    network_config: NeuralFieldConfig
    network_shape: FieldShape
    train: np.ndarray
    validation: np.ndarray | None
    tv_weight: float = 0.0
    tv_rise: float = 0.0

    def tv_weight_at(self, step: int) -> float:
        """The total variation's weight at ``step`` (0-based): ``tv_rise`` times the steps
        taken, up to ``tv_weight`` (``tv_rise`` 0: ``tv_weight`` from the start)."""
        if self.tv_rise <= 0:
            return self.tv_weight
        return min(self.tv_weight, self.tv_rise * (step + 1))


@dataclass(frozen=True, eq=False)
class TrainedVolume:
    """What a backend's training returns: the albedo (Z, Y, X) in the normalised units,
    the history ({step, loss}), the last loss and the network's parameter count."""

    albedo: np.ndarray
    history: list[dict[str, float]]
    final_loss: float
    n_parameters: int
    steps: int = 0
    """Steps taken (fewer than ``steps`` when ``patience`` stopped the training)."""
    best_validation: float | None = None
    """The kept step's validation error (relative, as the loss); None: no validation."""


def volume_coordinates(depths: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(x, y, z) of every voxel (Z * Y * X, 3), each axis scaled into [-MARGIN, MARGIN]
    (an axis with one value: 0), float32."""
    def scaled(a: np.ndarray) -> np.ndarray:
        span = float(a.max() - a.min())
        return np.zeros_like(a) if span == 0 else MARGIN * (2 * (a - a.min()) / span - 1)

    z, y, x = np.meshgrid(scaled(depths), scaled(ys), scaled(xs), indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=-1).astype(np.float32)


class NeuralVolumeFieldModel(FieldModel[NeuralVolumeConfig]):
    """A network's non-negative albedo on ``rsd_prior``'s lattice (see the module
    docstring). A backend subclass sets ``backend`` and implements :meth:`network_class`
    and :meth:`train`."""

    config_class = NeuralVolumeConfig
    family = "neural_volume"
    backend: ClassVar[str] = ""
    """The backend of the network (``torch``, ``jax``)."""

    def __init__(self, config: NeuralVolumeConfig | Mapping[str, object] | None = None
                 ) -> None:
        super().__init__(config)
        self._scene: RSDPriorFieldModel | None = None
        self._n_network = 0

    @classmethod
    def model_name(cls) -> str:
        """The registered name, e.g. ``neural_volume_torch`` (also the tag in saved files)."""
        return f"{cls.family}_{cls.backend}"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The field-model class of network ``name`` on this backend (its factory and
        config class build the albedo's network)."""
        raise NotImplementedError(f"{cls.__name__} names no backend")

    def train(self, problem: VolumeProblem,
              on_step: Callable[[TrainingStep], None] | None = None) -> TrainedVolume:
        """Train the network on ``problem`` (the backend's)."""
        raise NotImplementedError(f"{type(self).__name__} names no backend")

    @classmethod
    def use_threads(cls, threads: int) -> None:
        """From the calling thread's next step, train on ``threads`` CPU threads (called
        from a step callback inside :meth:`train`); a backend without a thread setting
        ignores it."""

    def stack_copies(self, confocal: bool) -> int:
        """How many copies of :func:`plane_stack`'s arrays host memory holds while
        training (the stack itself, and any reordered copy the backend's operator makes)."""
        return 1

    @classmethod
    def held_stacks(cls, config: NeuralVolumeConfig, confocal: bool) -> float:
        """How many stacks' worth host memory holds at the training's peak, for the run's
        memory estimate (a backend that holds less than :meth:`stack_copies`' bound says
        so). Default: :meth:`stack_copies`."""
        return float(cls(config).stack_copies(confocal))

    @classmethod
    def estimate_memory(cls, config: NeuralVolumeConfig, shape: PlanShape) -> MemoryEstimate:
        """The operator on the lattice, its planes bounded from the run's depth range, and
        the network's training (:mod:`nlosfw.model.hybrid.volume_memory`)."""
        network = cls.network_config(cls.network_class(config.network), config)
        return volume_memory(config.prior_config(), network, cls.backend,
                             cls.held_stacks(config, shape.confocal), shape,
                             averaged=config.average_steps)

    def learning_rate(self, step: int) -> float:
        """Adam's learning rate at ``step`` (0-based): cosine from ``lr`` to ``lr * lr_final``."""
        cfg = self.config
        return learning_rate(NeuralFieldConfig(steps=cfg.steps, lr=cfg.lr, lr_final=cfg.lr_final),
                             step)

    # ------------------------------------------------------------------ fit
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Train the network's albedo on ``field`` (``validation`` is unused: the held-out
        points are ``validation_fraction`` of the field's)."""
        start = time.perf_counter()
        who = self.model_name()
        check_training_field(field, who)
        network = self.network_class(self.config.network)   # a bad name fails first
        problem, lattice, scale, prior = self._problem(field, network,
                                                       self.config.prior_config())
        fitted = {"lobe_exponent": prior.lobe.exponent} if self.config.prior.lobe.fit else {}
        trained = self.train(problem, on_step)
        albedo = np.asarray(trained.albedo, dtype=np.float32)
        if albedo.shape != problem.gain.shape or not np.all(np.isfinite(albedo)):
            raise FitError(f"{who}: training diverged (non-finite albedo); lower model.lr")
        self._scene = RSDPriorFieldModel.from_albedo(prior, lattice, albedo, field.geometry,
                                                     scale)
        self._n_network = trained.n_parameters
        steps = trained.steps or self.config.steps
        return FitReport(steps=steps, seconds=time.perf_counter() - start,
                         final_loss=trained.final_loss, history=trained.history,
                         best_val_loss=trained.best_validation, fitted=fitted,
                         stopped_early=steps < self.config.steps)

    def _problem(self, field: PhasorField, network: type[NeuralFieldModel],
                 prior: RSDPriorConfig
                 ) -> tuple[VolumeProblem, VoxelLattice, float, RSDPriorConfig]:
        """(What the backend trains on, the lattice, the field's scale, ``prior`` with its
        lobe fixed): ``rsd_prior``'s setup with options ``prior`` (its depth planes, lattice,
        frequencies, lobe and normalisation). With ``lobe.fit``, ``rsd_prior``'s held-out
        search on this lattice (at its default frequency count) fixes the lobe first."""
        cfg, who = self.config, self.model_name()
        check_geometry(field.geometry)
        samples, values, scale = training_values(field, who)      # rsd_prior's
        with options_in_group("prior"):
            lattice, chosen = RSDPriorFieldModel(prior).plan_lattice(values, samples, field)
        if prior.lobe.fit:
            search = replace(prior, fit_frequencies=RSDPriorConfig().fit_frequencies)
            picked = fitted_frequencies(search.fit_frequencies, field, lattice.depths)
            exponent = RSDPriorFieldModel(search).search_lobe(field, values, samples, lattice,
                                                              picked)
            prior = replace(prior, lobe=replace(prior.lobe, fit=False, exponent=exponent))
        dtype = np.complex64 if prior.precision == Precision.single else np.complex128
        op = SceneOperator(lattice, samples.layout, field.geometry, field.frequencies[chosen],
                           OperatorOptions(amplitude=prior.amplitude, lobe=prior.lobe.exponent,
                                           dtype=dtype, workers=prior.workers, cache_mb=0.0),
                           samples.mask)
        need, room = stack_bytes(op) * self.stack_copies(op.confocal), available_memory()
        log.info("%s: operator of %d planes x %d frequencies on a %d x %d lattice: %s",
                 who, lattice.depths.size, op.frequencies.size, *op.conv.shape,
                 format_bytes(need))
        if room is not None and need > room:
            raise FitError(f"{who}: its operator ({lattice.depths.size} depth planes x "
                           f"{op.frequencies.size} frequencies) needs {format_bytes(need)}, "
                           f"but {format_bytes(room)} are available; lower "
                           "model.prior.fit_frequencies or narrow model.prior.depth.range")
        data = np.ascontiguousarray(values[chosen]).astype(dtype)
        norms = op.column_norms()
        peak = float((op.adjoint(data).real / norms).max())
        if not peak > 0:
            raise FitError(f"{who}: no non-negative albedo correlates with the field "
                           "(max Re(A^H P) <= 0); check the capture geometry and the field's sign")
        net_config = self.network_config(network, cfg)
        shape = FieldShape(FieldMode.multi, lattice.shape, int(lattice.depths.size))
        ys, xs = lattice.axes()
        train, validation = validation_split(samples.layout.shape, cfg.validation_fraction,
                                             cfg.seed, samples.mask)
        if validation is not None and not np.any(np.abs(data) * validation):
            validation = None          # silent validation points (dead pixels): no error to compare
        return VolumeProblem(
            stack=plane_stack(op), data=data,
            coords=volume_coordinates(lattice.depths, ys, xs),
            gain=np.full(norms.shape, peak / float(np.mean(norms)), dtype=np.float32),
            shift=float(np.log(np.expm1(cfg.albedo_start))),
            network=network, network_config=net_config, network_shape=shape,
            train=train, validation=validation,
            tv_weight=cfg.albedo_tv / max(1.0, float(np.sum(train))),
            tv_rise=cfg.albedo_tv_rise), lattice, scale, prior

    @classmethod
    def check_config(cls, config: NeuralVolumeConfig) -> None:
        """The network must be registered for this backend, take ``network_options`` and
        the device."""
        network = cls.network_class(config.network)
        network.check_config(cls.network_config(network, config))

    @staticmethod
    def network_config(network: type[NeuralFieldModel], config: NeuralVolumeConfig
                       ) -> NeuralFieldConfig:
        """The albedo network's config: ``config``'s widths, seed, device, steps, learning
        rate and threads, and its ``network_options`` (errors name them as the user does:
        ``model.lr``, ``model.network_options.levels``)."""
        options = {"seed": config.seed, "device": config.device,
                   "hidden": list(config.network_hidden), "steps": config.steps,
                   "lr": config.lr, "threads": config.threads, "validation_fraction": 0.0,
                   **config.network_options}
        built: NeuralFieldConfig = wrapped_network_config(
            network.config_class, options, VOLUME_NAMES, "network_options")
        return built

    # ------------------------------------------------------------------ predict
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """The fitted volume's field at wall points (..., 2) and frequencies (F,) -> (F, ...)."""
        xy, f = check_query(wall_xy, frequencies, self.model_name())
        return self._fitted_scene().predict(xy, f)

    def _fitted_scene(self) -> RSDPriorFieldModel:
        if self._scene is None:
            raise FitError(f"{self.model_name()}: call fit() or load() before predict() or "
                           "save()")
        return self._scene

    @property
    def albedo(self) -> np.ndarray:
        """The fitted albedo (Z, Y, X) (normalised units) on ``rsd_prior``'s lattice."""
        return self._fitted_scene().albedo

    @property
    def scene(self) -> RSDPriorFieldModel:
        """The fitted albedo as an ``rsd_prior`` model (its lattice, geometry, scale)."""
        return self._fitted_scene()

    @property
    def n_parameters(self) -> int:
        """The network's trainable parameters."""
        if self._scene is None:
            raise FitError(f"{self.model_name()}: the number of parameters is known after "
                           "fit or load")
        return self._n_network

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        """One file: the config, the parameter count and the albedo's ``rsd_prior`` file."""
        scene = self._fitted_scene()
        with tempfile.TemporaryDirectory() as tmp:
            scene_path = Path(tmp) / "scene"
            scene.save(scene_path)
            data = np.frombuffer(scene_path.read_bytes(), dtype=np.uint8)
        write_model_file(path, self.model_name(), self.config, {"scene_file": data},
                         {"backend": self.backend, "family": self.family,
                          "n_parameters": self._n_network})

    @classmethod
    def load(cls, path: str | Path) -> NeuralVolumeFieldModel:
        header, arrays = read_model_file(path, cls.model_name())
        try:
            model = cls(stored_config(cls.config_class, header))
            stored = np.asarray(arrays["scene_file"], dtype=np.uint8).tobytes()
            n_network = int(header["n_parameters"])
        except (KeyError, TypeError, ValueError, ConfigError) as err:
            raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                            f"({type(err).__name__})") from None
        with tempfile.TemporaryDirectory() as tmp:
            scene_path = Path(tmp) / "scene"
            scene_path.write_bytes(stored)
            try:
                scene = RSDPriorFieldModel.load(scene_path)
            except DataError as err:
                raise DataError(f"model file {path}: invalid {cls.model_name()} file "
                                f"(its albedo: {err})") from None
        model._scene, model._n_network = scene, n_network
        return model

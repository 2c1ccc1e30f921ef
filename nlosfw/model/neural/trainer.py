"""The shared trainer: a neural field model is a network plus this, whatever the backend.

:class:`NeuralFieldModel` implements :class:`~nlosfw.model.FieldModel` once for
every network: normalisation, inputs, batches, the validation split, the
learning-rate schedule, early stopping, divergence detection, seeding, files and
prediction. A network plugin supplies only ``factory(config, shape)`` (a torch
module or a JAX module) and the backend's :class:`~nlosfw.model.neural.backend.Backend`
runs its steps; the ``register_networks`` hook (:mod:`nlosfw.plugins.networks`) turns a
registered network into a subclass of this class named ``<network>_<backend>``.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlosfw.common.config import config_from_mapping
from nlosfw.common.deprecation import REMOVED_IN
from nlosfw.common.errors import DataError, FitError
from nlosfw.common.memory import MemoryEstimate, PlanShape
from nlosfw.model.interface import (
    FieldModel,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, write_model_file
from nlosfw.model.neural.backend import PREDICT_CHUNK, Backend, NetworkBuild
from nlosfw.model.neural.config import (
    FieldMode,
    FieldShape,
    NeuralFieldConfig,
    Preset,
)
from nlosfw.model.neural.memory import field_shape, network_memory
from nlosfw.model.neural.normalisation import FieldNormalisation
from nlosfw.model.neural.smoothness import FrequencySmoothness
from nlosfw.model.neural.steps import BatchStream, field_inputs, learning_rate
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)


class NeuralFieldModel(FieldModel[NeuralFieldConfig]):
    """A neural field F(x, y, f) -> P (multi mode) or one F_f(x, y) per frequency (single).

    A subclass names its network and backend (:func:`nlosfw.plugins.network_model` makes
    one from a registered network): ``family`` (the network's name), ``backend``
    (``torch``, ``jax``), ``backend_class``, ``network_factory`` and ``config_class``.
    """

    config_class: ClassVar[type] = NeuralFieldConfig
    family: ClassVar[str] = ""
    """The network's registered name (``siren``, ``example_fourier``, ...)."""
    backend: ClassVar[str] = ""
    """The backend that runs it (``torch``, ``jax``)."""
    backend_class: ClassVar[type[Backend]]
    network_factory: ClassVar[Callable[..., Any]]
    network_presets: ClassVar[Mapping[str, Preset]] = {}

    def __init_subclass__(cls, **kwargs: object) -> None:
        """A subclass that sets ``engine_class``, ``backend_class``'s old name, gets it as
        ``backend_class`` (with a DeprecationWarning)."""
        super().__init_subclass__(**kwargs)
        old = cls.__dict__.get("engine_class")
        if old is not None and "backend_class" not in cls.__dict__:
            warnings.warn(f"{cls.__name__}.engine_class is deprecated and will be removed in "
                          f"nlosfw {REMOVED_IN}: set backend_class", DeprecationWarning,
                          stacklevel=2)
            cls.backend_class = old

    def __init__(self, config: NeuralFieldConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._shape: FieldShape | None = None
        self._norm: FieldNormalisation | None = None
        self._net: Backend | None = None
        self._train_frequencies: np.ndarray | None = None
        self.report: FitReport | None = None
        self.lr_option = "model.lr"
        """The option that sets ``lr`` as the user names it (in errors); a model wrapping
        this network names its own (``model.network_lr``)."""

    # ------------------------------------------------------------------ naming
    @classmethod
    def model_name(cls) -> str:
        """The registered name, e.g. ``siren_torch`` (also the tag in saved files)."""
        return f"{cls.family}_{cls.backend}"

    @classmethod
    def check_config(cls, config: NeuralFieldConfig) -> None:
        """Before a run: the engine can use ``config.device`` on this machine."""
        cls.backend_class.check_device(config.device)

    @classmethod
    def estimate_memory(cls, config: NeuralFieldConfig, shape: PlanShape) -> MemoryEstimate:
        """The backend's runtime, the training samples and batch, the network's parameters
        and the history (:mod:`nlosfw.model.neural.memory`)."""
        return network_memory(config, cls.backend, field_shape(shape, FieldMode(config.mode)),
                              shape.samples)

    @classmethod
    def presets(cls) -> dict[str, Preset]:
        """Published configurations of this network (e.g. the thesis's), by name."""
        return dict(cls.network_presets)

    def _make_net(self, shape: FieldShape, n_networks: int,
                  state: Mapping[str, np.ndarray] | None = None, who: str = "") -> Backend:
        """The backend's network (``n_networks`` of them in single mode), from ``state``."""
        factory = type(self).network_factory        # a plain function, not a method
        build = NetworkBuild(factory, self.config, shape, n_networks, who or self.model_name())
        return self.backend_class(build, state)

    # ------------------------------------------------------------------ sizes
    @property
    def is_fitted(self) -> bool:
        return self._net is not None

    @property
    def n_networks(self) -> int:
        """Networks trained: 1 in multi mode, one per training frequency in single mode."""
        if self.config.mode == FieldMode.multi:
            return 1
        if self._train_frequencies is None:
            raise FitError(f"{self.model_name()}: the number of single-frequency networks is "
                           "known after fit or load")
        return int(self._train_frequencies.size)

    @property
    def parameters_per_network(self) -> int:
        """Trainable parameters of one network (before fit: when the config alone fixes it)."""
        if self._net is not None:
            return self._net.parameters_per_network
        try:
            net = self._make_net(FieldShape(self.config.mode), 0)
        except FitError as err:
            raise FitError(f"{self.model_name()}: the network's size follows the training "
                           f"data; it is known after fit or load ({err})") from None
        return net.parameters_per_network

    @property
    def n_parameters(self) -> int:
        """Trainable parameters of all networks (single mode: per network times networks)."""
        n_networks = self.n_networks
        return self.parameters_per_network * n_networks

    def weights(self) -> list[np.ndarray]:
        """The trained parameters as numpy arrays, in the network's order."""
        return self._fitted()[0].parameters()

    # ------------------------------------------------------------------ training
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Train on ``field`` with Adam; see :class:`~nlosfw.model.NeuralFieldConfig`.

        ``validation`` (optional) replaces the random held-out fraction of training
        samples for early stopping. ``on_step`` receives a :class:`TrainingStep` every
        ``eval_every`` steps and at the end; time spent in it is not counted as training
        time (``seconds``, ``max_seconds``). Raises :class:`FitError` on divergence.
        """
        who = self.model_name()
        check_training_field(field, who)
        cfg: NeuralFieldConfig = self.config
        single = cfg.mode == FieldMode.single
        norm = FieldNormalisation.fit(field, cfg.margin, cfg.demodulate)
        shape = FieldShape.of(cfg.mode, field)
        rng = np.random.default_rng([cfg.seed, 0x6261746368])  # "batch" stream
        x, y = self._samples(norm, field)
        n = x.shape[0]
        val_x: np.ndarray | None
        val_y: np.ndarray | None
        if validation is not None:
            check_training_field(validation, f"{who} validation")
            if single and (validation.frequencies.shape != field.frequencies.shape or not
                           np.allclose(validation.frequencies, field.frequencies)):
                raise DataError(f"{who}: in single mode the validation field must have the "
                                "training frequencies")
            val_x, val_y = self._samples(norm, validation)
            train_idx = np.arange(n)
        elif cfg.validation_fraction > 0 and n >= 20:
            perm = rng.permutation(n)
            n_val = max(1, int(round(cfg.validation_fraction * n)))
            val_sel, train_idx = np.sort(perm[:n_val]), np.sort(perm[n_val:])
            val_x = x[val_sel]
            val_y = y[:, val_sel] if single else y[val_sel]
        else:
            val_x = val_y = None
            train_idx = np.arange(n)
        tx = x[train_idx]
        ty = y[:, train_idx] if single else y[train_idx]
        n_networks = field.n_frequencies if single else 0
        net = self._make_net(shape, n_networks)
        n_params, n_values = net.parameters_per_network * max(1, n_networks), \
            2 * field.values.size
        if n_params > 0.5 * n_values:
            log.warning("%s: %d parameters for %d training values (%.0f%%): more than half "
                        "tends to over-fit and upsample badly (thesis sec. 4.2); consider "
                        "smaller hidden layers", who, n_params, n_values,
                        100 * n_params / n_values)
        net.set_data(tx, ty, val_x, val_y)
        self._shape, self._norm, self._net = shape, norm, net
        self._train_frequencies = field.frequencies.copy() if single else None
        smooth = FrequencySmoothness.of(
            cfg.frequency_smoothness, cfg.smoothness_points, x[:, :2],
            norm.freqs(field.frequencies), single,
            np.random.default_rng([cfg.seed, 0x736D6F6F7468]))  # "smooth" stream
        try:
            self.report = self._train(net, tx.shape[0], val_x is not None, rng, on_step,
                                      smooth)
        except BaseException:
            # a failed (diverged, interrupted) fit leaves no half-trained model behind
            self._shape = self._norm = self._net = self._train_frequencies = None
            raise
        return self.report

    def _samples(self, norm: FieldNormalisation, field: PhasorField
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Network inputs and normalised targets of every sample of ``field``."""
        xy = norm.coords(field.wall_xyz[..., :2].reshape(-1, 2))
        n_f, n_p = field.n_frequencies, xy.shape[0]
        y = norm.targets(field.values.reshape(n_f, n_p), field.frequencies)    # (F, P, 2)
        if self.config.mode == FieldMode.single:
            return field_inputs(xy), y
        return field_inputs(xy, norm.freqs(field.frequencies)), y.reshape(-1, 2)

    def _train(self, net: Backend, n_train: int, has_val: bool, rng: np.random.Generator,
               on_step: Callable[[TrainingStep], None] | None,
               smooth: FrequencySmoothness | None = None) -> FitReport:
        cfg: NeuralFieldConfig = self.config
        batch = cfg.batch_size if 0 < cfg.batch_size < n_train else 0
        stream = BatchStream(n_train, batch, rng) if batch else None
        start = time.perf_counter()
        history: list[dict[str, float]] = []
        handles: list[Any] = []
        first_loss = best_val = math.inf
        best_snapshot: Any = None
        bad_evals, stopped_early, loss, val = 0, False, math.nan, None
        step, paused = 0, 0.0           # paused: time spent in on_step, not training
        while step < cfg.steps:
            handle = net.step(stream.next() if stream else None, learning_rate(cfg, step),
                                 smooth.batch() if smooth else None)
            handles.append(handle)
            step += 1
            if step == 1:
                first_loss = net.mean_loss([handle])
                self._check_divergence(first_loss, math.inf, step)
            elapsed = time.perf_counter() - start - paused
            out_of_time = cfg.max_seconds > 0 and elapsed >= cfg.max_seconds
            if step % cfg.eval_every and step < cfg.steps and not out_of_time:
                continue
            loss = net.mean_loss(handles)
            handles = []
            self._check_divergence(loss, first_loss, step)
            val = None
            if has_val:
                val = net.val_loss()
                self._check_divergence(val, math.inf, step)
                if val < best_val:
                    best_val, best_snapshot, bad_evals = val, net.snapshot(), 0
                else:
                    bad_evals += 1
            seconds = time.perf_counter() - start - paused
            history.append({"step": step, "loss": loss, "seconds": seconds,
                            **({"val_loss": val} if val is not None else {})})
            if on_step is not None:
                t_cb = time.perf_counter()
                on_step(TrainingStep(step=step, total_steps=cfg.steps, loss=loss,
                                     val_loss=val, seconds=seconds))
                paused += time.perf_counter() - t_cb
            if out_of_time:
                break
            if cfg.patience and bad_evals >= cfg.patience:
                stopped_early = True
                break
        if best_snapshot is not None and val is not None and best_val < val:
            net.restore(best_snapshot)
        seconds = time.perf_counter() - start - paused
        log.info("%s: %d steps in %.1f s, loss %.3g, best validation %s", self.model_name(),
                 step, seconds, loss, f"{best_val:.3g}" if has_val else "n/a")
        return FitReport(steps=step, seconds=seconds, final_loss=float(loss),
                         best_val_loss=float(best_val) if has_val else None,
                         stopped_early=stopped_early, history=history)

    def _check_divergence(self, loss: float, first_loss: float, step: int) -> None:
        limit = self.config.divergence_factor * first_loss
        if not math.isfinite(loss) or loss > limit:
            raise FitError(f"{self.model_name()}: training diverged at step {step} (loss "
                           f"{loss:.3g}, first loss {first_loss:.3g}); lower {self.lr_option} "
                           f"(now {self.config.lr:g})")

    # ------------------------------------------------------------------ prediction
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Complex field (F, ...) at wall points (..., 2) and frequencies (F,), complex64.

        Single mode: a frequency between two training frequencies gets the linear
        blend of their two networks' (demodulated) fields; outside the training band,
        the nearest network's; the common delay's carrier e^{-2 pi i f delay} of the
        requested frequency is then put back (see ``demodulate``).
        """
        xy, f = check_query(wall_xy, frequencies, self.model_name())
        net, norm, _ = self._fitted()
        shape = xy.shape[:-1]
        pts = norm.coords(xy.reshape(-1, 2))
        n_p = pts.shape[0]
        if self.config.mode == FieldMode.single:
            out = self._predict_single(net, norm, pts, f)
        else:
            out = np.empty((f.size, n_p), dtype=np.complex64)
            fn = norm.freqs(f)
            per_chunk = max(1, PREDICT_CHUNK * 4 // max(n_p, 1))
            for k in range(0, f.size, per_chunk):
                sl = slice(k, k + per_chunk)
                y = net.forward(field_inputs(pts, fn[sl]))
                out[sl] = norm.values(y.reshape(-1, n_p, 2), f[sl])
        return out.reshape((f.size, *shape))

    def _predict_single(self, net: Backend, norm: FieldNormalisation, pts: np.ndarray,
                        f: np.ndarray) -> np.ndarray:
        trained = self._train_frequencies
        if trained is None:
            raise FitError(f"{self.model_name()}: single-mode model without its frequencies")
        order = np.argsort(trained)
        ft = trained[order]
        pos = np.clip(np.searchsorted(ft, f), 1, max(1, ft.size - 1))
        lo = np.clip(pos - 1, 0, ft.size - 1)
        hi = np.clip(pos, 0, ft.size - 1)
        span = np.where(ft[hi] > ft[lo], ft[hi] - ft[lo], 1.0)
        w = np.clip((f - ft[lo]) / span, 0.0, 1.0)
        w = np.where(ft[hi] > ft[lo], w, 0.0)
        i0, i1 = order[lo], order[hi]
        needed = np.unique(np.concatenate([i0, i1]))
        values = norm.values(net.forward(field_inputs(pts), needed), trained[needed])
        where = {int(k): j for j, k in enumerate(needed)}
        v0 = values[[where[int(k)] for k in i0]]
        v1 = values[[where[int(k)] for k in i1]]
        # blend the demodulated fields, then put the carrier of the requested frequency back
        c0 = np.exp(2j * np.pi * (trained[i0] - f) * norm.delay)[:, None]
        c1 = np.exp(2j * np.pi * (trained[i1] - f) * norm.delay)[:, None]
        return ((1 - w)[:, None] * v0 * c0 + w[:, None] * v1 * c1).astype(np.complex64)

    def _fitted(self) -> tuple[Backend, FieldNormalisation, FieldShape]:
        if self._net is None or self._norm is None or self._shape is None:
            raise FitError(f"{self.model_name()}: call fit() or load() before predict() or "
                           "save()")
        return self._net, self._norm, self._shape

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        """Write the network's state, config, data shape and normalisation to one ``.npz``."""
        net, norm, shape = self._fitted()
        extra: dict[str, Any] = {"field_shape": shape.to_dict(),
                                 "normalisation": norm.to_dict(),
                                 "backend": self.backend, "family": self.family}
        if self._train_frequencies is not None:
            extra["train_frequencies"] = [float(v) for v in self._train_frequencies]
        write_model_file(path, self.model_name(), self.config, net.state(), extra)

    @classmethod
    def load(cls, path: str | Path, *, allow_other_backend: bool = False) -> NeuralFieldModel:
        """Read a file written by :meth:`save` of this model.

        With ``allow_other_backend`` a file of the same network written by another
        backend (e.g. ``siren_jax`` into ``siren_torch``) is accepted as well: networks
        registered for both backends name their arrays alike.
        """
        names: tuple[str, ...] = (cls.model_name(),)
        if allow_other_backend:
            names += tuple(f"{cls.family}_{b}" for b in ("torch", "jax") if b != cls.backend)
        header, arrays = read_model_file(path, names)
        try:
            config: NeuralFieldConfig = config_from_mapping(cls.config_class, header["config"],
                                                            "model")
            norm = FieldNormalisation.from_dict(header["normalisation"])
            trained = header.get("train_frequencies")
            if "field_shape" in header:
                shape = FieldShape.from_dict(header["field_shape"])
            else:
                shape, arrays = _version_1_network(header, arrays, config)
        except Exception as err:
            raise DataError(f"model file {path}: invalid header ({type(err).__name__}: "
                            f"{err})") from None
        single = config.mode == FieldMode.single
        n_networks = len(trained) if single and trained else 0
        if single and not n_networks:
            raise DataError(f"model file {path}: single-mode model without its frequencies")
        model = cls(config)
        try:
            net = model._make_net(shape, n_networks, arrays, f"model file {path}")
        except FitError as err:
            raise DataError(str(err)) from None
        model._shape, model._norm, model._net = shape, norm, net
        model._train_frequencies = np.asarray(trained, dtype=float) if n_networks else None
        return model


def _version_1_network(header: Mapping[str, Any], arrays: Mapping[str, np.ndarray],
                       config: NeuralFieldConfig) -> tuple[FieldShape, dict[str, np.ndarray]]:
    """The data shape and named state of a file written before networks were pluggable.

    Those files (the thesis networks only) stored the resolved architecture and the
    arrays [W0, b0, W1, b1, ...] as ``p0``, ``p1``, ...; a grid of 2^L points per side
    (and 2^L_f frequencies) resolves the same octaves again.
    """
    arch = header["architecture"]
    octaves, f_octaves = int(arch.get("octaves", 0)), int(arch.get("frequency_octaves", 0))
    shape = FieldShape(config.mode, (2 ** octaves, 2 ** octaves) if octaves else None,
                       2 ** f_octaves if f_octaves else None)
    n_arrays = len([k for k in arrays if k.startswith("p")])
    state = {f"layers.{i // 2}.{'bias' if i % 2 else 'weight'}": arrays[f"p{i}"]
             for i in range(n_arrays)}
    return shape, state

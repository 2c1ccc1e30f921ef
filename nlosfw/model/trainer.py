"""The training loop, prediction and files of neural field models, whatever the backend.

:class:`NeuralFieldModel` implements :class:`~nlosfw.model.FieldModel` once;
a backend plugin (torch, JAX) subclasses it and supplies an :class:`Engine`
that holds the parameters and Adam's state on its device and runs steps and
forward passes. Everything else (normalisation, initial weights, batches, the
learning-rate schedule, validation, early stopping, divergence detection,
files) is shared, so both backends train the same network from the same start
on the same batches.
"""

from __future__ import annotations

import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.interface import FieldModel, FitReport, TrainingStep
from nlosfw.model.networks import (
    Architecture,
    FieldNormalisation,
    NeuralFieldConfig,
    Preset,
    check_query,
    check_training_field,
    count_parameters,
    init_parameters,
    learning_rate,
    network_inputs,
    params_from_arrays,
    presets_of,
    read_model_file,
    resolve_architecture,
    write_model_file,
)
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

#: Rows per forward pass when predicting or validating (bounds memory).
PREDICT_CHUNK = 1 << 16


class Engine(ABC):
    """Backend half of a neural field: parameters and optimiser state on one device.

    Data layout. Multi mode: inputs ``x`` (N, in_dim), targets ``y`` (N, 2).
    Single mode (``n_networks`` = K > 0): inputs ``x`` (P, in_dim) shared by the K
    networks, targets ``y`` (K, P, 2); parameters carry a leading axis K. Batch
    indices always index the N (or P) axis. The loss is the mean squared error
    over every element of the batch (and every network).
    """

    def __init__(self, arch: Architecture, params: list[np.ndarray], n_networks: int,
                 device: str, threads: int) -> None:
        self.arch = arch
        self.n_networks = n_networks

    @abstractmethod
    def set_data(self, x: np.ndarray, y: np.ndarray, val_x: np.ndarray | None,
                 val_y: np.ndarray | None) -> None:
        """Move training (and validation) arrays to the device."""

    @abstractmethod
    def step(self, idx: np.ndarray | None, lr: float) -> Any:
        """One Adam step on the batch ``idx`` (None: all data); returns a loss handle."""

    @abstractmethod
    def mean_loss(self, handles: list[Any]) -> float:
        """Mean of the losses behind ``handles`` (synchronises with the device)."""

    @abstractmethod
    def val_loss(self) -> float:
        """Mean squared error on the validation data."""

    @abstractmethod
    def snapshot(self) -> Any:
        """A copy of the current parameters that :meth:`restore` can bring back."""

    @abstractmethod
    def restore(self, snapshot: Any) -> None:
        """Bring back parameters saved by :meth:`snapshot`."""

    @abstractmethod
    def parameters(self) -> list[np.ndarray]:
        """The current parameters as float32 numpy arrays [W0, b0, W1, b1, ...]."""

    @abstractmethod
    def forward(self, x: np.ndarray, networks: np.ndarray | None = None) -> np.ndarray:
        """Outputs (N, 2) of the network, or (len(networks), N, 2) of some single-mode networks."""


class _IndexStream:
    """Batches of sample indices: consecutive slices of fresh random permutations."""

    def __init__(self, n: int, batch: int, rng: np.random.Generator) -> None:
        self.n, self.batch, self.rng = n, batch, rng
        self.perm = rng.permutation(n)
        self.pos = 0

    def next(self) -> np.ndarray:
        parts, need = [], self.batch
        while need > 0:
            if self.pos >= self.n:
                self.perm, self.pos = self.rng.permutation(self.n), 0
            take = self.perm[self.pos:self.pos + need]
            parts.append(take)
            self.pos += take.size
            need -= take.size
        return np.concatenate(parts).astype(np.int64)


class NeuralFieldModel(FieldModel):
    """A neural field F(x, y, f) -> P (multi mode) or one F_f(x, y) per frequency (single).

    Subclasses set :attr:`family` (``tanh``, ``pe``, ``siren``), :attr:`backend`, the
    matching ``config_class`` and implement :meth:`make_engine`.
    """

    config_class: ClassVar[type] = NeuralFieldConfig
    family: ClassVar[str] = ""
    backend: ClassVar[str] = ""

    def __init__(self, config: Any = None) -> None:
        super().__init__(config)
        self._arch: Architecture | None = None
        self._norm: FieldNormalisation | None = None
        self._engine: Engine | None = None
        self._train_frequencies: np.ndarray | None = None
        self.report: FitReport | None = None

    # ------------------------------------------------------------------ naming
    @classmethod
    def model_name(cls) -> str:
        """The registered name, e.g. ``siren_torch`` (also the tag in saved files)."""
        return f"{cls.family}_{cls.backend}"

    @classmethod
    def presets(cls) -> dict[str, Preset]:
        """The thesis presets of this family (see :data:`nlosfw.model.networks.PRESETS`)."""
        return presets_of(cls.family)

    @abstractmethod
    def make_engine(self, arch: Architecture, params: list[np.ndarray],
                    n_networks: int) -> Engine:
        """The backend engine for ``arch`` starting from ``params``."""

    # ------------------------------------------------------------------ sizes
    @property
    def is_fitted(self) -> bool:
        return self._engine is not None

    @property
    def n_networks(self) -> int:
        """Networks trained: 1 in multi mode, one per training frequency in single mode."""
        if self.config.mode == "multi":
            return 1
        if self._train_frequencies is None:
            raise FitError(f"{self.model_name()}: the number of single-frequency networks is "
                           "known after fit or load")
        return int(self._train_frequencies.size)

    @property
    def architecture(self) -> Architecture:
        """The resolved network (after fit or load; before, when the config alone fixes it)."""
        if self._arch is not None:
            return self._arch
        auto_pe = self.family == "pe" and (
            self.config.octaves == 0 or (self.config.mode == "multi"
                                         and self.config.frequency_input == "encoded"
                                         and self.config.frequency_octaves == 0))
        if auto_pe:
            raise FitError(f"{self.model_name()}: the positional encoding's octaves follow the "
                           "training grid; the architecture is known after fit or load")
        return resolve_architecture(self.family, self.config, (1, 1), 1)

    @property
    def parameters_per_network(self) -> int:
        return self.architecture.parameters_per_network

    @property
    def n_parameters(self) -> int:
        """Trainable parameters of all networks (single mode: per network times networks)."""
        return count_parameters(self.architecture, self.n_networks)

    def weights(self) -> list[np.ndarray]:
        """The trained parameters as numpy arrays [W0, b0, W1, b1, ...] (W: fan_in x fan_out)."""
        return self._fitted()[0].parameters()

    # ------------------------------------------------------------------ training
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Train on ``field`` with Adam; see :class:`~nlosfw.model.networks.NeuralFieldConfig`.

        ``validation`` (optional) replaces the random held-out fraction of training
        samples for early stopping. ``on_step`` receives a :class:`TrainingStep` every
        ``eval_every`` steps and at the end; time spent in it is not counted as training
        time (``seconds``, ``max_seconds``). Raises :class:`FitError` on divergence.
        """
        who = self.model_name()
        check_training_field(field, who)
        cfg: NeuralFieldConfig = self.config
        single = cfg.mode == "single"
        norm = FieldNormalisation.fit(field, cfg.margin, cfg.demodulate)
        arch = resolve_architecture(self.family, cfg, field.grid_shape, field.n_frequencies)
        rng = np.random.default_rng([cfg.seed, 0x6261746368])  # "batch" stream
        x, y = self._samples(arch, norm, field)
        n = x.shape[0]
        if validation is not None:
            check_training_field(validation, f"{who} validation")
            if single and (validation.frequencies.shape != field.frequencies.shape or not
                           np.allclose(validation.frequencies, field.frequencies)):
                raise DataError(f"{who}: in single mode the validation field must have the "
                                "training frequencies")
            val_x, val_y = self._samples(arch, norm, validation)
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
        n_params, n_values = count_parameters(arch, n_networks), 2 * field.values.size
        if n_params > 0.5 * n_values:
            log.warning("%s: %d parameters for %d training values (%.0f%%): more than half "
                        "tends to over-fit and upsample badly (thesis sec. 4.2); consider "
                        "smaller hidden layers", who, n_params, n_values,
                        100 * n_params / n_values)
        params = init_parameters(arch, n_networks, cfg.seed)
        engine = self.make_engine(arch, params, n_networks)
        engine.set_data(tx, ty, val_x, val_y)
        self._arch, self._norm, self._engine = arch, norm, engine
        self._train_frequencies = field.frequencies.copy() if single else None
        try:
            self.report = self._train(engine, tx.shape[0], val_x is not None, rng, on_step)
        except BaseException:
            # a failed (diverged, interrupted) fit leaves no half-trained model behind
            self._arch = self._norm = self._engine = self._train_frequencies = None
            raise
        return self.report

    def _samples(self, arch: Architecture, norm: FieldNormalisation, field: PhasorField
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Network inputs and normalised targets of every sample of ``field``."""
        xy = norm.coords(field.wall_xyz[..., :2].reshape(-1, 2))
        n_f, n_p = field.n_frequencies, xy.shape[0]
        y = norm.targets(field.values.reshape(n_f, n_p), field.frequencies)    # (F, P, 2)
        if self.config.mode == "single":
            return network_inputs(arch, xy), y
        return network_inputs(arch, xy, norm.freqs(field.frequencies)), y.reshape(-1, 2)

    def _train(self, engine: Engine, n_train: int, has_val: bool, rng: np.random.Generator,
               on_step: Callable[[TrainingStep], None] | None) -> FitReport:
        cfg: NeuralFieldConfig = self.config
        batch = cfg.batch_size if 0 < cfg.batch_size < n_train else 0
        stream = _IndexStream(n_train, batch, rng) if batch else None
        start = time.perf_counter()
        history: list[dict[str, float]] = []
        handles: list[Any] = []
        first_loss = best_val = math.inf
        best_snapshot: Any = None
        bad_evals, stopped_early, loss, val = 0, False, math.nan, None
        step, paused = 0, 0.0           # paused: time spent in on_step, not training
        while step < cfg.steps:
            handle = engine.step(stream.next() if stream else None, learning_rate(cfg, step))
            handles.append(handle)
            step += 1
            if step == 1:
                first_loss = engine.mean_loss([handle])
                self._check_divergence(first_loss, math.inf, step)
            elapsed = time.perf_counter() - start - paused
            out_of_time = cfg.max_seconds > 0 and elapsed >= cfg.max_seconds
            if step % cfg.eval_every and step < cfg.steps and not out_of_time:
                continue
            loss = engine.mean_loss(handles)
            handles = []
            self._check_divergence(loss, first_loss, step)
            val = None
            if has_val:
                val = engine.val_loss()
                self._check_divergence(val, math.inf, step)
                if val < best_val:
                    best_val, best_snapshot, bad_evals = val, engine.snapshot(), 0
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
            engine.restore(best_snapshot)
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
                           f"{loss:.3g}, first loss {first_loss:.3g}); lower model.lr "
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
        engine, norm, arch = self._fitted()
        shape = xy.shape[:-1]
        pts = norm.coords(xy.reshape(-1, 2))
        n_p = pts.shape[0]
        if self.config.mode == "single":
            out = self._predict_single(engine, arch, norm, pts, f)
        else:
            out = np.empty((f.size, n_p), dtype=np.complex64)
            fn = norm.freqs(f)
            per_chunk = max(1, PREDICT_CHUNK * 4 // max(n_p, 1))
            for k in range(0, f.size, per_chunk):
                sl = slice(k, k + per_chunk)
                y = engine.forward(network_inputs(arch, pts, fn[sl]))
                out[sl] = norm.values(y.reshape(-1, n_p, 2), f[sl])
        return out.reshape((f.size, *shape))

    def _predict_single(self, engine: Engine, arch: Architecture, norm: FieldNormalisation,
                        pts: np.ndarray, f: np.ndarray) -> np.ndarray:
        trained = self._train_frequencies
        assert trained is not None
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
        x = network_inputs(arch, pts)
        values = norm.values(engine.forward(x, needed), trained[needed])  # (len(needed), P)
        where = {int(k): j for j, k in enumerate(needed)}
        v0 = values[[where[int(k)] for k in i0]]
        v1 = values[[where[int(k)] for k in i1]]
        # blend the demodulated fields, then put the carrier of the requested frequency back
        c0 = np.exp(2j * np.pi * (trained[i0] - f) * norm.delay)[:, None]
        c1 = np.exp(2j * np.pi * (trained[i1] - f) * norm.delay)[:, None]
        return ((1 - w)[:, None] * v0 * c0 + w[:, None] * v1 * c1).astype(np.complex64)

    def _fitted(self) -> tuple[Engine, FieldNormalisation, Architecture]:
        if self._engine is None or self._norm is None or self._arch is None:
            raise FitError(f"{self.model_name()}: call fit() or load() before predict() or "
                           "save()")
        return self._engine, self._norm, self._arch

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        """Write weights, config, architecture and normalisation to one ``.npz`` file."""
        engine, norm, arch = self._fitted()
        params = engine.parameters()
        extra: dict[str, Any] = {"architecture": arch.to_dict(), "normalisation": norm.to_dict(),
                                 "backend": self.backend, "family": self.family}
        if self._train_frequencies is not None:
            extra["train_frequencies"] = [float(v) for v in self._train_frequencies]
        write_model_file(path, self.model_name(), self.config,
                         {f"p{i}": p for i, p in enumerate(params)}, extra)

    @classmethod
    def load(cls, path: str | Path, *, allow_other_backend: bool = False) -> NeuralFieldModel:
        """Read a file written by :meth:`save` of this model.

        With ``allow_other_backend`` a file of the same family written by another
        backend (e.g. ``siren_jax`` into ``siren_torch``) is accepted as well: the
        weight layout is shared.
        """
        names: tuple[str, ...] = (cls.model_name(),)
        if allow_other_backend:
            names += tuple(f"{cls.family}_{b}" for b in ("torch", "jax") if b != cls.backend)
        header, arrays = read_model_file(path, names)
        try:
            config = config_from_mapping(cls.config_class, header["config"], "model")
            arch = Architecture.from_dict(header["architecture"])
            norm = FieldNormalisation.from_dict(header["normalisation"])
            trained = header.get("train_frequencies")
        except Exception as err:
            raise DataError(f"model file {path}: invalid header ({type(err).__name__}: "
                            f"{err})") from None
        n_networks = len(trained) if config.mode == "single" and trained else 0
        if config.mode == "single" and not n_networks:
            raise DataError(f"model file {path}: single-mode model without its frequencies")
        params = params_from_arrays(path, arch, n_networks, arrays)
        model = cls(config)
        model._arch, model._norm = arch, norm
        model._train_frequencies = np.asarray(trained, dtype=float) if n_networks else None
        model._engine = model.make_engine(arch, params, n_networks)
        return model

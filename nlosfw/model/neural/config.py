"""What every neural field shares: the training options and the shape of the data a
network is built for.

A network plugin declares its options as a dataclass deriving from
:class:`NeuralFieldConfig` (the architecture's own fields added), and a factory
``factory(config, shape)`` that builds the network for a :class:`FieldShape`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any, TypedDict, TypeVar

from nlosfw.common.config import Choice, config_from_mapping, require, require_threads
from nlosfw.common.errors import ConfigError
from nlosfw.model.interface import FieldModelConfig
from nlosfw.transform.field import PhasorField


class FieldMode(Choice):
    """How the field is split across networks."""

    multi = "multi"
    """One network F(x, y, f)."""
    single = "single"
    """One network F_f(x, y) per training frequency, all trained at once as a batch."""


class LRSchedule(Choice):
    """Decay of the learning rate after warm-up."""

    constant = "constant"
    cosine = "cosine"
    exponential = "exponential"


def set_choice(config: Any, option: str, choices: type[Enum]) -> None:
    """Turn the plain string in ``config.option`` into its :class:`Enum` member (in place, in
    ``__post_init__`` of a frozen config); a one-line :class:`ConfigError` lists the valid ones."""
    value = getattr(config, option)
    try:
        member = choices(value)
    except ValueError:
        valid = ", ".join(m.value for m in choices)
        raise ConfigError(option, f"must be one of {valid}, got {value!r}") from None
    object.__setattr__(config, option, member)


#: The most wall points of the smoothness penalty per step (a thousand times the default;
#: each is evaluated at every frequency of its difference stencil every step).
MAX_SMOOTHNESS_POINTS = 65536


@dataclass(frozen=True)
class NeuralFieldConfig(FieldModelConfig):
    """Options shared by every neural field model (architecture, training, normalisation)."""

    mode: FieldMode = FieldMode.multi
    """``multi``: one network F(x, y, f); ``single``: one network F_f(x, y) per training
    frequency (other frequencies are interpolated linearly between the two nearest networks)."""
    hidden: tuple[int, ...] = (32, 32, 32, 32)
    """Widths of the hidden layers."""
    steps: int = 3000
    """Number of Adam steps (upper bound when early stopping or ``max_seconds`` stops sooner)."""
    batch_size: int = 8192
    """Training samples per step (in ``single`` mode: pixels per network); 0 = full batch."""
    lr: float = 1e-3
    """Peak learning rate of Adam."""
    lr_schedule: LRSchedule = LRSchedule.cosine
    """Decay after warm-up: constant, cosine or exponential down to ``lr * lr_final``."""
    lr_final: float = 0.05
    """Final learning rate as a fraction of ``lr`` (cosine and exponential)."""
    warmup_steps: int = 0
    """Steps of linear warm-up from lr/100 to lr."""
    validation_fraction: float = 0.05
    """Fraction of the training samples held out for early stopping (0: none)."""
    eval_every: int = 100
    """Steps between validation evaluations (and progress reports)."""
    patience: int = 0
    """Evaluations without a validation improvement before stopping (0: never stop early).
    The weights of the best evaluation are kept in every case."""
    max_seconds: float = 0.0
    """[s] Wall-clock budget of the training loop (0: none)."""
    margin: float = 0.9
    """Inputs and targets are scaled into [-margin, margin], inside the open interval (-1, 1)."""
    divergence_factor: float = 1e3
    """Training fails when the loss exceeds this factor times the first loss (or is NaN)."""
    threads: int = 1
    """CPU threads of torch while this model trains (0: torch's default, one per core;
    prediction always uses torch's default). One is the default: training batches are too
    small to gain much from intra-op threads, and two threads slow down ten-fold when
    another process shares the cores. JAX ignores it (XLA chooses)."""
    demodulate: bool = True
    """Multiply the field by e^{+2 pi i f tau} with tau the energy centroid of its transient
    (a common path delay) before fitting, and undo it on prediction: the field then turns
    far fewer times across the band (a normalisation of the targets; exact, no information
    lost)."""
    frequency_smoothness: float = 0.0
    """Weight of the regularisation across frequency (0: off): the mean squared second
    difference of the normalised field between neighbouring frequencies (at the mean
    training spacing), at random wall points, added to the loss. The field is smooth
    in frequency; this keeps a network from wiggling between training frequencies
    (:mod:`nlosfw.model.neural.smoothness`). Needs 3 or more training frequencies."""
    smoothness_points: int = 64
    """Random wall points of that penalty per step (multi mode: each at its own random
    frequency of the band; single mode: every network at the same points)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        set_choice(self, "mode", FieldMode)
        set_choice(self, "lr_schedule", LRSchedule)
        require(len(self.hidden) >= 1 and all(h >= 1 for h in self.hidden), "hidden",
                f"needs at least one layer width >= 1, got {list(self.hidden)}")
        require(self.steps >= 1, "steps", f"must be >= 1, got {self.steps}")
        require(self.batch_size >= 0, "batch_size", f"must be >= 0 (0: full batch), got "
                f"{self.batch_size}")
        require(self.lr > 0 and math.isfinite(self.lr), "lr", f"must be > 0, got {self.lr}")
        require(0 < self.lr_final <= 1, "lr_final", f"must be in (0, 1], got {self.lr_final}")
        require(self.warmup_steps >= 0, "warmup_steps", f"must be >= 0, got {self.warmup_steps}")
        require(0 <= self.validation_fraction < 0.5, "validation_fraction",
                f"must be in [0, 0.5), got {self.validation_fraction}")
        require(self.eval_every >= 1, "eval_every", f"must be >= 1, got {self.eval_every}")
        require(self.patience >= 0, "patience", f"must be >= 0, got {self.patience}")
        require(self.max_seconds >= 0, "max_seconds", f"must be >= 0, got {self.max_seconds}")
        require(0 < self.margin < 1, "margin",
                f"must be in (0, 1) so data stay in the open interval (-1, 1), got {self.margin}")
        require(self.divergence_factor > 1, "divergence_factor",
                f"must be > 1, got {self.divergence_factor}")
        require_threads(self.threads, "threads", 0, "the backend's default")
        require(self.frequency_smoothness >= 0 and math.isfinite(self.frequency_smoothness),
                "frequency_smoothness", f"must be >= 0 (0: off), got "
                f"{self.frequency_smoothness}")
        require(1 <= self.smoothness_points <= MAX_SMOOTHNESS_POINTS, "smoothness_points",
                f"must be 1 to {MAX_SMOOTHNESS_POINTS}, got {self.smoothness_points}")

    def network_shapes(self, shape: FieldShape) -> dict[str, tuple[int, ...]]:
        """The arrays of one network of these options for data of ``shape`` (trainable and
        fixed, by name, with the shapes its initial state has), from the options alone:
        nothing is allocated and no backend imported, so the memory a network needs is
        known before a run. Default: an MLP ``in_dim -> hidden -> out_dim``
        (:func:`mlp_shapes`); a network of another layout overrides it."""
        return mlp_shapes([shape.in_dim, *self.hidden, shape.out_dim])

    def activation_widths(self) -> int:
        """The units one training sample's activations take in a batch (the hidden layers'
        widths; an encoding that adds outputs of its own counts them): what the memory
        estimate multiplies by the batch (:mod:`nlosfw.model.neural.memory`)."""
        return sum(self.hidden)


C = TypeVar("C")


def wrapped_network_config(config_class: type[C], options: Mapping[str, object],
                           names: Mapping[str, str], others: str = "") -> C:
    """The config of a network another model wraps (a residual, a volume's albedo), built
    from ``options``; an error names the option as the user spells it: ``model.<name>``
    for the network options ``names`` maps to the wrapping model's own, else
    ``model.<others>.<option>`` (``others``: where the wrapping model takes the network's
    own options)."""
    try:
        return config_from_mapping(config_class, options)
    except ConfigError as err:
        head, dot, rest = err.option.partition(".")
        name = names.get(head) or ".".join(p for p in (others, head) if p)
        raise ConfigError(".".join(p for p in ("model", name) if p) + dot + rest,
                          err.problem) from None


def mlp_shapes(dims: list[int], prefix: str = "") -> dict[str, tuple[int, ...]]:
    """The arrays of linear layers ``dims[0] -> ... -> dims[-1]``: ``<prefix>layers.<i>.weight``
    (fan_in, fan_out) and ``<prefix>layers.<i>.bias`` (fan_out,)."""
    shapes: dict[str, tuple[int, ...]] = {}
    for i, (fan_in, fan_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        shapes[f"{prefix}layers.{i}.weight"] = (int(fan_in), int(fan_out))
        shapes[f"{prefix}layers.{i}.bias"] = (int(fan_out),)
    return shapes


class FieldShapeDict(TypedDict):
    """A :class:`FieldShape` as plain values."""

    mode: str
    grid_shape: list[int] | None
    n_frequencies: int | None


@dataclass(frozen=True)
class FieldShape:
    """What a network factory is told about the data it will fit.

    The network maps normalised inputs (N, ``in_dim``), float32, each in (-1, 1) —
    columns x, y (and f in ``multi`` mode) — to (N, 2) = (Re P, Im P), or to a
    complex (N,). ``grid_shape`` and ``n_frequencies`` describe the training field
    (a network may size itself from them, e.g. octaves of an encoding); they are
    None when a model is asked for its size before it has seen data, and a factory
    that needs them raises :class:`~nlosfw.common.FitError` then.
    """

    mode: FieldMode
    grid_shape: tuple[int, int] | None = None
    """(Y, X) of the training wall grid; for scattered samples (a field with one row of
    N irregular wall points) the square grid of about as many, (s, s) with s = round(sqrt N)."""
    n_frequencies: int | None = None
    """Training frequencies."""

    @property
    def in_dim(self) -> int:
        """Input columns: 3 (x, y, f) in multi mode, 2 (x, y) in single mode."""
        return 3 if self.mode == FieldMode.multi else 2

    @property
    def out_dim(self) -> int:
        """Output columns (Re, Im)."""
        return 2

    @classmethod
    def of(cls, mode: FieldMode, field: PhasorField) -> FieldShape:
        """The shape of a training field (a grid, or scattered samples)."""
        ny, nx = field.grid_shape
        if ny == 1 and nx > 1 and field.grid_spacing() is None:     # scattered samples
            side = max(1, int(round(math.sqrt(nx))))
            return cls(mode, (side, side), field.n_frequencies)
        return cls(mode, (ny, nx), field.n_frequencies)

    def to_dict(self) -> FieldShapeDict:
        """Plain values for a model file's header."""
        return {"mode": FieldMode(self.mode).value,
                "grid_shape": list(self.grid_shape) if self.grid_shape else None,
                "n_frequencies": self.n_frequencies}

    @classmethod
    def from_dict(cls, data: FieldShapeDict) -> FieldShape:
        """Inverse of :meth:`to_dict`."""
        grid = data.get("grid_shape")
        n_f = data.get("n_frequencies")
        return cls(mode=FieldMode(data["mode"]),
                   grid_shape=(int(grid[0]), int(grid[1])) if grid else None,
                   n_frequencies=int(n_f) if n_f is not None else None)


@dataclass(frozen=True)
class Preset:
    """A named set of options reproducing one published network (e.g. thesis Table 4.1)."""

    family: str
    """The network it configures (``siren``, ``pe``, ...)."""
    options: Mapping[str, Any]
    parameters: int
    """Trainable parameters of one network, as published."""
    description: str = ""

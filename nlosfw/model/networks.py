"""Backend-neutral pieces of the implicit neural phasor fields (thesis ch. 4), numpy only.

The torch and JAX plugins read the same config dataclasses, presets,
initial weights, normalisation and file format from here, so the two backends
train the same network from the same starting point on the same batches.

Networks (``hidden`` = widths of the hidden layers, output = (Re P, Im P)):

* ``tanh``: inputs -> tanh layers -> linear output, Glorot-uniform weights.
* ``pe``: NeRF's positional encoding gamma(x) = (sin(2^l pi x), cos(2^l pi x))
  for l < L per coordinate, then ReLU (or tanh) layers -> linear output.
* ``siren``: sin(omega0 (W x + b)) layers with Sitzmann's initialisation ->
  linear output.

In ``multi`` mode one network maps (x, y, f) to P; in ``single`` mode one
network per training frequency maps (x, y) to P_f (all of them are trained at
once as a batch of independent networks).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nlosfw.common.config import Choice, config_from_mapping, config_to_dict, require
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.interface import FieldModelConfig
from nlosfw.transform.field import PhasorField

#: Format tag written in every field-model file.
FILE_FORMAT = "nlosfw-field-model"
FILE_VERSION = 1


# --------------------------------------------------------------------------- configs
class NetworkMode(Choice):
    """One network F(x, y, f) for every frequency, or one F_f(x, y) per frequency."""

    multi = "multi"
    single = "single"


class LrSchedule(Choice):
    """How the learning rate decays after warm-up."""

    constant = "constant"
    cosine = "cosine"
    exponential = "exponential"


class FrequencyInput(Choice):
    """How a multi-frequency PE network sees the frequency."""

    raw = "raw"
    encoded = "encoded"


class Activation(Choice):
    """Activation of a PE network's hidden layers."""

    relu = "relu"
    tanh = "tanh"


@dataclass(frozen=True)
class NeuralFieldConfig(FieldModelConfig):
    """Options shared by every neural field model (architecture, training, normalisation)."""

    mode: NetworkMode = NetworkMode.multi
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
    lr_schedule: LrSchedule = LrSchedule.cosine
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
    """Wall-clock budget of the training loop in seconds (0: none)."""
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

    def __post_init__(self) -> None:
        super().__post_init__()
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
        require(self.threads >= 0, "threads", f"must be >= 0, got {self.threads}")


@dataclass(frozen=True)
class TanhFieldConfig(NeuralFieldConfig):
    """A plain MLP with tanh activations (the thesis's first model)."""

    hidden: tuple[int, ...] = (64, 64, 64)
    lr: float = 3e-3


@dataclass(frozen=True)
class PEFieldConfig(NeuralFieldConfig):
    """An MLP on NeRF's positional encoding of (x, y) (and optionally of f)."""

    hidden: tuple[int, ...] = (64, 64, 64)
    lr: float = 3e-3
    octaves: int = 0
    """L, the number of octaves of gamma(x, y); 0: 2^L closest to the training resolution."""
    include_input: bool = False
    """Also feed the raw (normalised) x and y to the network."""
    frequency_input: FrequencyInput = FrequencyInput.encoded
    """Multi mode: pass the normalised frequency raw (as the thesis), or encoded with gamma
    as well (default: a raw f cannot make the field turn across the band; held-out error
    on the two-planes benchmark 1.1 raw against 0.75 encoded, ReLU)."""
    frequency_octaves: int = 0
    """Octaves of gamma(f) when ``frequency_input`` is ``encoded`` (0: 2^L closest to the
    number of training frequencies)."""
    activation: Activation = Activation.tanh
    """Activation of the hidden layers (NeRF uses ReLU; tanh fits phasor fields better:
    held-out error 0.52 against 0.75 on the two-planes benchmark)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(0 <= self.octaves <= 16, "octaves", f"must be in [0, 16], got {self.octaves}")
        require(0 <= self.frequency_octaves <= 16, "frequency_octaves",
                f"must be in [0, 16], got {self.frequency_octaves}")


@dataclass(frozen=True)
class SirenFieldConfig(NeuralFieldConfig):
    """SIREN (Sitzmann 2020): sine activations sin(omega0 (W x + b))."""

    hidden: tuple[int, ...] = (64, 64, 64)
    lr: float = 2e-3
    omega0_first: float = 15.0
    """omega0 of the first layer (sets the bandwidth the network starts with; Sitzmann's 30
    fits noise more and held-out samples less on the benchmark's phasor fields)."""
    omega0_hidden: float = 30.0
    """omega0 of the hidden layers."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.omega0_first > 0, "omega0_first", f"must be > 0, got {self.omega0_first}")
        require(self.omega0_hidden > 0, "omega0_hidden",
                f"must be > 0, got {self.omega0_hidden}")


#: Config class of each network family.
FAMILY_CONFIGS: dict[str, type[NeuralFieldConfig]] = {
    "tanh": TanhFieldConfig,
    "pe": PEFieldConfig,
    "siren": SirenFieldConfig,
}


# --------------------------------------------------------------------------- presets
@dataclass(frozen=True)
class Preset:
    """A named set of options reproducing one network of the thesis (Table 4.1)."""

    family: str
    options: Mapping[str, Any]
    parameters: int
    """Trainable parameters of one network, as printed in the thesis."""
    description: str = ""


_THESIS_TRAINING = {"lr": 1e-3, "lr_schedule": "constant", "batch_size": 0, "steps": 100_000,
                    "validation_fraction": 0.0}

#: The thesis's four networks (ch. 4, Table 4.1) with its training recipe (lr 1e-3, full
#: batch, 100,000 steps: about 9 h on 2 CPU cores; override ``steps`` for a quicker fit).
PRESETS: dict[str, Preset] = {
    "thesis_tanh_single": Preset(
        "tanh", {"mode": "single", "hidden": (20, 20, 20), **_THESIS_TRAINING}, 942,
        "MLP + tanh, one frequency: 2 -> 20 -> 20 -> 20 -> 2"),
    "thesis_pe_single": Preset(
        "pe", {"mode": "single", "hidden": (16, 16, 16), "octaves": 5, "include_input": False,
               "activation": "relu", **_THESIS_TRAINING}, 914,
        "MLP + positional encoding (L = 5, no raw input), one frequency: 20 -> 16 x3 -> 2"),
    "thesis_pe_multi": Preset(
        "pe", {"mode": "multi", "hidden": (32, 32, 32, 32), "octaves": 5,
               "include_input": False, "frequency_input": "raw", "activation": "relu",
               **_THESIS_TRAINING}, 3938,
        "MLP + positional encoding of (x, y) and raw f: 21 -> 32 x4 -> 2"),
    "thesis_siren": Preset(
        "siren", {"mode": "multi", "hidden": (32, 32, 32, 32), "omega0_first": 30.0,
                  "omega0_hidden": 30.0, **_THESIS_TRAINING}, 3362,
        "SIREN, multi frequency: 3 -> 32 x4 (sine) -> 2 (linear)"),
}


def presets_of(family: str) -> dict[str, Preset]:
    """The presets of one network family (``tanh``, ``pe`` or ``siren``)."""
    return {name: p for name, p in PRESETS.items() if p.family == family}


def preset_config(name: str, **overrides: Any) -> NeuralFieldConfig:
    """The config of preset ``name`` with some options overridden (e.g. ``steps=2000``)."""
    if name not in PRESETS:
        raise DataError(f"preset: unknown preset {name!r}; valid: {', '.join(sorted(PRESETS))}")
    preset = PRESETS[name]
    return config_from_mapping(FAMILY_CONFIGS[preset.family], {**preset.options, **overrides},
                               "model")


# --------------------------------------------------------------------------- architecture
def default_octaves(resolution: int) -> int:
    """L such that 2^L is closest to ``resolution`` (thesis: 32 samples -> L = 5), at least 1."""
    return max(1, int(round(math.log2(max(int(resolution), 1)))))


@dataclass(frozen=True)
class Architecture:
    """Everything needed to build, count and evaluate a network, resolved against the data."""

    family: str
    mode: str
    in_dim: int
    hidden: tuple[int, ...]
    out_dim: int = 2
    activation: str = "tanh"
    """``tanh``, ``relu`` or ``sine``."""
    octaves: int = 0
    include_input: bool = True
    frequency_input: str = "raw"
    frequency_octaves: int = 0
    omega0_first: float = 30.0
    omega0_hidden: float = 30.0

    @property
    def layer_shapes(self) -> list[tuple[int, int]]:
        """(fan_in, fan_out) of every linear layer, the output layer last."""
        dims = [self.in_dim, *self.hidden, self.out_dim]
        return [(dims[i], dims[i + 1]) for i in range(len(dims) - 1)]

    @property
    def parameters_per_network(self) -> int:
        return sum(i * o + o for i, o in self.layer_shapes)

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Architecture:
        data = dict(data)
        data["hidden"] = tuple(int(h) for h in data["hidden"])
        return cls(**data)


def resolve_architecture(family: str, config: NeuralFieldConfig, grid_shape: tuple[int, int],
                         n_frequencies: int) -> Architecture:
    """The network of ``config`` for training data on a (Y, X) grid with F frequencies."""
    multi = config.mode == "multi"
    if family == "pe":
        _require_config(config, PEFieldConfig, family)
        octaves = config.octaves or default_octaves(max(grid_shape))
        f_oct = config.frequency_octaves or default_octaves(n_frequencies)
        in_dim = 2 * 2 * octaves + (2 if config.include_input else 0)
        if multi:
            in_dim += 1 if config.frequency_input == "raw" else 2 * f_oct
        return Architecture("pe", config.mode, in_dim, config.hidden,
                            activation=config.activation, octaves=octaves,
                            include_input=config.include_input,
                            frequency_input=config.frequency_input,
                            frequency_octaves=f_oct if config.frequency_input == "encoded" else 0)
    in_dim = 3 if multi else 2
    if family == "siren":
        _require_config(config, SirenFieldConfig, family)
        return Architecture("siren", config.mode, in_dim, config.hidden, activation="sine",
                            omega0_first=config.omega0_first,
                            omega0_hidden=config.omega0_hidden)
    if family == "tanh":
        return Architecture("tanh", config.mode, in_dim, config.hidden, activation="tanh")
    raise DataError(f"unknown network family {family!r}; valid: {', '.join(FAMILY_CONFIGS)}")


def _require_config(config: NeuralFieldConfig, cls: type, family: str) -> None:
    if not isinstance(config, cls):
        raise DataError(f"model: the {family} family needs a {cls.__name__}, got "
                        f"{type(config).__name__}")


def count_parameters(arch: Architecture, n_networks: int = 1) -> int:
    """Trainable parameters: sum of (fan_in + 1) * fan_out over layers, times the networks."""
    return arch.parameters_per_network * max(1, n_networks)


def positional_encoding(u: np.ndarray, octaves: int) -> np.ndarray:
    """NeRF's gamma (thesis eq. 4.3) of every column of ``u`` (N, D) -> (N, 2 D L).

    Per coordinate: sin(2^0 pi u), cos(2^0 pi u), ..., sin(2^(L-1) pi u), cos(2^(L-1) pi u).
    """
    u = np.asarray(u, dtype=np.float64)
    scales = np.pi * 2.0 ** np.arange(octaves)
    arg = u[:, :, None] * scales[None, None, :]                      # (N, D, L)
    enc = np.stack([np.sin(arg), np.cos(arg)], axis=-1)              # (N, D, L, 2)
    return enc.reshape(u.shape[0], -1)


def spatial_features(arch: Architecture, xy: np.ndarray) -> np.ndarray:
    """Per-point input columns from normalised coordinates (P, 2): gamma(x, y) and/or x, y."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if arch.family != "pe":
        return xy
    parts = [positional_encoding(xy, arch.octaves)]
    if arch.include_input:
        parts.append(xy)
    return np.concatenate(parts, axis=1)


def frequency_features(arch: Architecture, f: np.ndarray) -> np.ndarray:
    """Per-frequency input columns from normalised frequencies (F,): f, or gamma(f)."""
    f = np.asarray(f, dtype=np.float64).reshape(-1, 1)
    if arch.family == "pe" and arch.frequency_input == "encoded":
        return positional_encoding(f, arch.frequency_octaves)
    return f


def network_inputs(arch: Architecture, xy: np.ndarray, f: np.ndarray | None = None
                   ) -> np.ndarray:
    """Network inputs (float32) from normalised coordinates (P, 2) and frequencies (F,).

    Single mode (``f`` None): (P, in_dim). Multi mode: (F * P, in_dim), frequency-major
    (row ``k * P + p`` is point p at frequency k).
    """
    spatial = spatial_features(arch, xy)
    if f is None:
        out = spatial
    else:
        spectral = frequency_features(arch, f)
        n_f, n_p = spectral.shape[0], spatial.shape[0]
        out = np.concatenate([np.tile(spatial, (n_f, 1)), np.repeat(spectral, n_p, axis=0)],
                             axis=1)
    if out.shape[1] != arch.in_dim:
        raise FitError(f"network inputs have {out.shape[1]} columns, the network expects "
                       f"{arch.in_dim}")
    return out.astype(np.float32)


def init_parameters(arch: Architecture, n_networks: int, seed: int) -> list[np.ndarray]:
    """Initial weights [W0, b0, W1, b1, ...] (float32), W of shape (fan_in, fan_out).

    With ``n_networks`` > 0 every array gets a leading axis of that length (single mode).
    tanh: Glorot-uniform weights, zero biases. pe: He-uniform (ReLU) or Glorot (tanh),
    zero biases. siren: first layer U(-1/n, 1/n), later layers
    U(-sqrt(6/n)/omega0, sqrt(6/n)/omega0), biases U(-1/sqrt(n), 1/sqrt(n)) (Sitzmann's
    code keeps PyTorch's default bias initialisation).
    """
    rng = np.random.default_rng([int(seed), 0x6669656C64])  # "field" stream
    lead = (n_networks,) if n_networks > 0 else ()
    params: list[np.ndarray] = []
    for i, (n_in, n_out) in enumerate(arch.layer_shapes):
        if arch.activation == "sine":
            bound = 1.0 / n_in if i == 0 else math.sqrt(6.0 / n_in) / arch.omega0_hidden
            b_bound = 1.0 / math.sqrt(n_in)
        elif arch.activation == "relu" and i < len(arch.layer_shapes) - 1:
            bound, b_bound = math.sqrt(6.0 / n_in), 0.0
        else:
            bound, b_bound = math.sqrt(6.0 / (n_in + n_out)), 0.0
        w = rng.uniform(-bound, bound, lead + (n_in, n_out))
        b = rng.uniform(-b_bound, b_bound, lead + (n_out,)) if b_bound else np.zeros(
            lead + (n_out,))
        params += [w.astype(np.float32), b.astype(np.float32)]
    return params


def forward_numpy(arch: Architecture, params: list[np.ndarray], x: np.ndarray) -> np.ndarray:
    """Reference forward pass in numpy (float64): (N, in) -> (N, 2), or batched (K, N, in).

    The backends implement the same function; tests compare them with this one.
    """
    h = np.asarray(x, dtype=np.float64)
    n_layers = len(params) // 2
    for i in range(n_layers):
        w = params[2 * i].astype(np.float64)
        b = params[2 * i + 1].astype(np.float64)
        z = h @ w + (b[..., None, :] if b.ndim == 2 else b)
        if i == n_layers - 1:
            return z
        if arch.activation == "sine":
            h = np.sin((arch.omega0_first if i == 0 else arch.omega0_hidden) * z)
        elif arch.activation == "relu":
            h = np.maximum(z, 0.0)
        else:
            h = np.tanh(z)
    return h


# --------------------------------------------------------------------------- normalisation
def estimate_delay(values: np.ndarray, frequencies: np.ndarray) -> float:
    """Energy centroid (metres of path) of the band-limited transient behind a field.

    ``values`` (F, ...) at ``frequencies`` (F,). E(tau) = sum over pixels of
    |sum_f P_f e^{+2 pi i f tau}|^2 is evaluated over one period of the frequency
    sampling, [-1/(2 df), 1/(2 df)) with df the smallest frequency step (so fields whose
    phase grows with f, i.e. negative delays, are handled too), and the centroid of the
    part above 1% of its peak (a circular mean: the axis is periodic) is returned.
    Multiplying the field by e^{+2 pi i f tau} removes that common delay: the field then
    turns fewer times
    across the band, which is what makes it easier to fit in f.
    """
    f = np.asarray(frequencies, dtype=np.float64)
    if f.size < 2:
        return 0.0
    v = np.asarray(values).reshape(f.size, -1)
    gaps = np.diff(np.sort(f))
    gaps = gaps[gaps > 1e-12 * f.max()]
    if gaps.size == 0:
        return 0.0
    period = 1.0 / float(gaps.min())
    n_tau = int(min(8192, math.ceil(8.0 * float(np.ptp(f)) * period)))
    taus = np.linspace(-period / 2, period / 2, n_tau, endpoint=False)
    kernel = np.exp(2j * np.pi * f[:, None] * taus[None, :])     # (F, T)
    energy = np.zeros(taus.size)
    for k in range(0, v.shape[1], 4096):
        energy += np.sum(np.abs(v[:, k:k + 4096].T @ kernel) ** 2, axis=0)
    keep = energy >= 0.01 * energy.max()
    # tau is periodic: take the circular mean. A delay modulo the period only changes a
    # global phase of the demodulated field (f * period is an integer plus a constant).
    turn = np.sum(energy[keep] * np.exp(2j * np.pi * taus[keep] / period))
    return float(period / (2 * np.pi) * np.angle(turn))


@dataclass(frozen=True)
class FieldNormalisation:
    """Affine maps of coordinates, frequency and values into [-margin, margin] ⊂ (−1, 1).

    x and y of the training points map their extent to [-margin, margin] (the same
    factor for both axes keeps the aspect ratio), f maps the training band likewise.
    Values are first demodulated by a common path delay (P e^{+2 pi i f delay},
    ``delay`` 0 when disabled), then Re and Im are divided by one common scale so that
    max(|Re|, |Im|) maps to ``margin`` (one scale preserves phases). Points outside the
    training hull map outside [-margin, margin] (extrapolation).
    """

    xy_center: tuple[float, float]
    xy_half: float
    f_center: float
    f_half: float
    value_scale: float
    margin: float
    delay: float = 0.0

    @classmethod
    def fit(cls, field: PhasorField, margin: float, demodulate: bool = False
            ) -> FieldNormalisation:
        xy = field.wall_xyz[..., :2].reshape(-1, 2)
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        half = float(np.max(hi - lo)) / 2
        f = field.frequencies
        f_half = float(f.max() - f.min()) / 2
        delay = estimate_delay(field.values, f) if demodulate else 0.0
        v = field.values * np.exp(2j * np.pi * f * delay)[:, None, None]
        peak = float(max(np.abs(v.real).max(), np.abs(v.imag).max()))
        if not peak > 0:
            raise FitError("field: all values are zero; nothing to fit")
        return cls(xy_center=(float(lo[0] + hi[0]) / 2, float(lo[1] + hi[1]) / 2),
                   xy_half=half if half > 0 else 1.0,
                   f_center=float(f.max() + f.min()) / 2,
                   f_half=f_half if f_half > 0 else float(f.max()),
                   value_scale=peak / margin, margin=float(margin), delay=delay)

    def coords(self, xy: np.ndarray) -> np.ndarray:
        """Normalised coordinates of wall points (..., 2) (float64)."""
        c = np.asarray(self.xy_center)
        return (np.asarray(xy, dtype=np.float64) - c) / self.xy_half * self.margin

    def freqs(self, f: np.ndarray) -> np.ndarray:
        """Normalised frequencies (float64)."""
        return (np.asarray(f, dtype=np.float64) - self.f_center) / self.f_half * self.margin

    def _carrier(self, f: np.ndarray, ndim: int) -> np.ndarray:
        f = np.asarray(f, dtype=np.float64)
        return np.exp(2j * np.pi * f * self.delay).reshape(f.shape + (1,) * (ndim - 1))

    def targets(self, values: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Complex values (F, ...) at ``frequencies`` (F,) -> normalised (F, ..., 2) float32."""
        values = np.asarray(values)
        v = values * self._carrier(frequencies, values.ndim) / self.value_scale
        return np.stack([v.real, v.imag], axis=-1).astype(np.float32)

    def values(self, outputs: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Network outputs (F, ..., 2) at ``frequencies`` (F,) -> complex values (complex64)."""
        out = np.asarray(outputs, dtype=np.float64)
        v = (out[..., 0] + 1j * out[..., 1]) * self.value_scale
        return (v / self._carrier(frequencies, v.ndim)).astype(np.complex64)

    def to_dict(self) -> dict[str, Any]:
        return {"xy_center": list(self.xy_center), "xy_half": self.xy_half,
                "f_center": self.f_center, "f_half": self.f_half,
                "value_scale": self.value_scale, "margin": self.margin, "delay": self.delay}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FieldNormalisation:
        return cls(xy_center=tuple(float(v) for v in data["xy_center"]),  # type: ignore[arg-type]
                   xy_half=float(data["xy_half"]), f_center=float(data["f_center"]),
                   f_half=float(data["f_half"]), value_scale=float(data["value_scale"]),
                   margin=float(data["margin"]), delay=float(data.get("delay", 0.0)))


# --------------------------------------------------------------------------- learning rate
def learning_rate(config: NeuralFieldConfig, step: int) -> float:
    """Learning rate of (0-based) ``step``: linear warm-up, then the configured decay."""
    lr, total = config.lr, config.steps
    if step < config.warmup_steps:
        return lr * (0.01 + 0.99 * step / config.warmup_steps)
    span = max(1, total - config.warmup_steps - 1)
    t = min(1.0, (step - config.warmup_steps) / span)
    if config.lr_schedule == "cosine":
        return lr * (config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * t)))
    if config.lr_schedule == "exponential":
        return lr * config.lr_final ** t
    return lr


# --------------------------------------------------------------------------- validation
def check_training_field(field: PhasorField, who: str) -> None:
    """One-line errors for fields nothing can be fitted to."""
    if not isinstance(field, PhasorField):
        raise DataError(f"{who}: fit needs a PhasorField, got {type(field).__name__}")
    if field.values.size == 0:
        raise FitError(f"{who}: the field is empty (shape {field.values.shape})")
    if not np.any(field.values != 0):
        raise FitError(f"{who}: the field's values are all zero; nothing to fit")


def check_query(wall_xy: Any, frequencies: Any, who: str) -> tuple[np.ndarray, np.ndarray]:
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


# --------------------------------------------------------------------------- files
def write_model_file(path: str | Path, model: str, config: Any, arrays: Mapping[str, np.ndarray],
                     extra: Mapping[str, Any] | None = None) -> None:
    """Write a portable ``.npz``: a JSON header (format, model name, config, extra) + arrays.

    ``path`` is used as given (no ``.npz`` suffix is appended).
    """
    header = {"format": FILE_FORMAT, "version": FILE_VERSION, "model": model,
              "config": config_to_dict(config), **dict(extra or {})}
    payload = {f"a_{k}": np.asarray(v) for k, v in arrays.items()}
    payload["header"] = np.array(json.dumps(header))
    with open(Path(path), "wb") as fh:
        np.savez(fh, **payload)


def read_model_file(path: str | Path, expected: str | tuple[str, ...]
                    ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of a file written by :func:`write_model_file` for model ``expected``.

    Raises a one-line :class:`DataError` for a missing, corrupt or foreign file.
    """
    path = Path(path)
    names = (expected,) if isinstance(expected, str) else tuple(expected)
    if not path.is_file():
        raise DataError(f"model file {path}: does not exist")
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"][()]))
            arrays = {k[2:]: np.array(data[k]) for k in data.files if k.startswith("a_")}
    except Exception as err:  # zipfile, pickle, json and key errors all mean "not ours"
        raise DataError(f"model file {path}: not a readable nlosfw field-model file "
                        f"(corrupt or another format: {type(err).__name__})") from None
    if not isinstance(header, dict) or header.get("format") != FILE_FORMAT:
        raise DataError(f"model file {path}: not an nlosfw field-model file")
    if header.get("version") != FILE_VERSION:
        raise DataError(f"model file {path}: format version {header.get('version')} is not "
                        f"supported (expected {FILE_VERSION})")
    if header.get("model") not in names:
        raise DataError(f"model file {path}: holds a {header.get('model')!r} field model, not "
                        f"{' or '.join(repr(n) for n in names)}")
    return header, arrays


def parameter_shapes(arch: Architecture, n_networks: int) -> list[tuple[int, ...]]:
    """Shapes of [W0, b0, W1, b1, ...]; a leading axis of ``n_networks`` when it is > 0."""
    lead = (n_networks,) if n_networks > 0 else ()
    shapes: list[tuple[int, ...]] = []
    for n_in, n_out in arch.layer_shapes:
        shapes += [lead + (n_in, n_out), lead + (n_out,)]
    return shapes


def params_from_arrays(path: str | Path, arch: Architecture, n_networks: int,
                       arrays: Mapping[str, np.ndarray]) -> list[np.ndarray]:
    """The parameter list stored in ``arrays`` (``p0``, ``p1``, ...) checked against ``arch``."""
    expected = parameter_shapes(arch, n_networks)
    params = []
    for i, shape in enumerate(expected):
        p = arrays.get(f"p{i}")
        if p is None or p.shape != shape or not np.all(np.isfinite(p)):
            got = None if p is None else p.shape
            raise DataError(f"model file {path}: parameter p{i} has shape {got}, the stored "
                            f"architecture needs {shape} (finite)")
        params.append(p.astype(np.float32))
    return params

"""The coordinate MLPs of the thesis (ch. 4), backend-neutral: options, architecture,
initial weights and a numpy reference forward pass.

Each network maps normalised (x, y[, f]) to (Re P, Im P); ``hidden`` = widths of
the hidden layers:

* ``tanh``: inputs -> tanh layers -> linear output, Glorot-uniform weights.
* ``pe``: NeRF's positional encoding gamma(x) = (sin(2^l pi x), cos(2^l pi x))
  for l < L per coordinate, then ReLU (or tanh) layers -> linear output.
* ``siren``: sin(omega0 (W x + b)) layers with Sitzmann's initialisation ->
  linear output.

The torch and JAX plugins register them as networks of the shared trainer
(:mod:`nlosfw.model.neural.trainer`; their registration and the thesis's presets:
:mod:`nlosfw.model.neural.catalogue`); their modules resolve the same
:class:`Architecture` and start from the same numpy weights (:func:`reference_state`), so
both backends train the same network from the same starting point. :func:`network_inputs`
and :func:`forward_numpy` are the independent reference the backends are checked against.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from nlosfw.common.config import Choice, require
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.neural.config import (
    FieldMode,
    FieldShape,
    NeuralFieldConfig,
    mlp_shapes,
    set_choice,
)

C = TypeVar("C", bound=NeuralFieldConfig)


class FrequencyInput(Choice):
    """How the PE network sees the frequency in multi mode."""

    raw = "raw"
    encoded = "encoded"


class PEActivation(Choice):
    """Activation of the PE network's hidden layers."""

    relu = "relu"
    tanh = "tanh"


# --------------------------------------------------------------------------- configs
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
    activation: PEActivation = PEActivation.tanh
    """Activation of the hidden layers (NeRF uses ReLU; tanh fits phasor fields better:
    held-out error 0.52 against 0.75 on the two-planes benchmark)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        set_choice(self, "frequency_input", FrequencyInput)
        set_choice(self, "activation", PEActivation)
        require(0 <= self.octaves <= 16, "octaves", f"must be in [0, 16], got {self.octaves}")
        require(0 <= self.frequency_octaves <= 16, "frequency_octaves",
                f"must be in [0, 16], got {self.frequency_octaves}")

    def network_shapes(self, shape: FieldShape) -> dict[str, tuple[int, ...]]:
        """The MLP on the encoded inputs (:func:`resolve_architecture`'s widths)."""
        arch = resolve_architecture("pe", self, shape.grid_shape, shape.n_frequencies)
        return mlp_shapes([arch.in_dim, *arch.hidden, arch.out_dim])


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


def resolve_architecture(family: str, config: NeuralFieldConfig,
                         grid_shape: tuple[int, int] | None, n_frequencies: int | None
                         ) -> Architecture:
    """The network of ``config`` for training data on a (Y, X) grid with F frequencies.

    ``grid_shape`` and ``n_frequencies`` may be None (no data yet) unless the positional
    encoding's octaves follow them (``octaves`` 0, or an encoded f with
    ``frequency_octaves`` 0): then a :class:`FitError` says so.
    """
    mode = FieldMode(config.mode).value
    multi = mode == FieldMode.multi.value
    if family == "pe":
        pe = _config_of(config, PEFieldConfig, family)
        encoded = multi and pe.frequency_input == FrequencyInput.encoded
        if (not pe.octaves and grid_shape is None) or (
                encoded and not pe.frequency_octaves and n_frequencies is None):
            raise FitError("model: the positional encoding's octaves follow the training grid; "
                           "the architecture is known after fit or load")
        octaves = pe.octaves or default_octaves(max(grid_shape or (1,)))
        f_oct = pe.frequency_octaves or default_octaves(n_frequencies or 1)
        in_dim = 2 * 2 * octaves + (2 if pe.include_input else 0)
        if multi:
            in_dim += 2 * f_oct if encoded else 1
        return Architecture("pe", mode, in_dim, pe.hidden,
                            activation=PEActivation(pe.activation).value, octaves=octaves,
                            include_input=pe.include_input,
                            frequency_input=FrequencyInput(pe.frequency_input).value,
                            frequency_octaves=f_oct if encoded else 0)
    in_dim = 3 if multi else 2
    if family == "siren":
        siren = _config_of(config, SirenFieldConfig, family)
        return Architecture("siren", mode, in_dim, siren.hidden, activation="sine",
                            omega0_first=siren.omega0_first,
                            omega0_hidden=siren.omega0_hidden)
    if family == "tanh":
        return Architecture("tanh", mode, in_dim, config.hidden, activation="tanh")
    raise DataError(f"unknown network family {family!r}; valid: {', '.join(FAMILY_CONFIGS)}")


def _config_of(config: NeuralFieldConfig, cls: type[C], family: str) -> C:
    if not isinstance(config, cls):
        raise DataError(f"model: the {family} family needs a {cls.__name__}, got "
                        f"{type(config).__name__}")
    return config


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


def parameter_names(arch: Architecture) -> list[str]:
    """Names of [W0, b0, W1, b1, ...] in a network's state: ``layers.<i>.weight`` / ``.bias``.

    The torch and JAX modules of the thesis networks use these names (W of shape
    (fan_in, fan_out)), so a file written by one backend loads in the other.
    """
    return [f"layers.{i}.{part}" for i in range(len(arch.layer_shapes))
            for part in ("weight", "bias")]


def reference_state(arch: Architecture, n_networks: int, seed: int) -> dict[str, np.ndarray]:
    """:func:`init_parameters` by name (see :func:`parameter_names`): the initial state the
    torch and JAX modules of the thesis networks start from."""
    return dict(zip(parameter_names(arch), init_parameters(arch, n_networks, seed), strict=True))


def thesis_architecture(config: NeuralFieldConfig, shape: FieldShape) -> Architecture:
    """The :class:`Architecture` of the thesis network ``config`` configures, for ``shape``
    (the family follows from the config's class: tanh, pe or siren)."""
    family = next((f for f, cls in FAMILY_CONFIGS.items() if type(config) is cls), None)
    if family is None:
        valid = ", ".join(c.__name__ for c in FAMILY_CONFIGS.values())
        raise DataError(f"model: {type(config).__name__} configures none of the thesis "
                        f"networks; valid: {valid}")
    return resolve_architecture(family, config, shape.grid_shape, shape.n_frequencies)


def uniform_layer(rng: np.random.Generator, lead: tuple[int, ...], fan_in: int, fan_out: int,
                  bound: float, bias_bound: float) -> tuple[np.ndarray, np.ndarray]:
    """The initial weights (``lead`` + (fan_in, fan_out)) and biases (``lead`` + (fan_out,))
    of one linear layer, U(-bound, bound) and U(-bias_bound, bias_bound), float32."""
    w = rng.uniform(-bound, bound, (*lead, fan_in, fan_out))
    b = rng.uniform(-bias_bound, bias_bound, (*lead, fan_out))
    return w.astype(np.float32), b.astype(np.float32)

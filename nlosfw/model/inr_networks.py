"""Four more neural fields (issue 12), backend-neutral: options, layout and initial weights.

* ``fourier`` (Tancik et al. 2020): features [cos 2 pi v B, sin 2 pi v B] of the inputs v
  with a fixed Gaussian matrix B (entries N(0, sigma^2)), then a ReLU MLP.
* ``wire`` (Saragadam et al. 2023): complex Gabor wavelet activations
  psi(z) = exp(i omega0 z - |s0 z|^2); the first layer is real, the later ones complex,
  and the network outputs the complex phasor itself.
* ``finer`` (Liu et al. 2024): the variable-periodic activation sin(omega0 (|z| + 1) z)
  with SIREN's weights and a wide first-layer bias U(-k, k).
* ``hashgrid`` (Mueller et al. 2022): a multiresolution hash-grid encoding of (x, y)
  (and of f in multi mode, unless ``encode_frequency`` is off), d-linear interpolation
  of trained feature tables, then a small ReLU MLP.

The torch and JAX plugins build the same modules (``nlosfw_torch.networks``,
``nlosfw_jax.networks``); both start from the numpy weights of :func:`field_network_state`,
so the two engines train the same network and read each other's files. Weights are
stored as real arrays (a complex weight as a leading axis (re, im)), so parameter
counts are counts of real numbers and Adam sees the same values in both engines.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import require
from nlosfw.common.errors import DataError, FitError
from nlosfw.model.neural_config import FieldMode, FieldShape, NeuralFieldConfig, mlp_shapes

#: Hashing primes of each grid axis (Mueller et al. 2022; the first axis is not scrambled).
HASH_PRIMES = (1, 2654435761, 805459861)


# --------------------------------------------------------------------------- configs
@dataclass(frozen=True)
class FourierFieldConfig(NeuralFieldConfig):
    """Fourier features (Tancik et al. 2020): a fixed Gaussian matrix B, then a ReLU MLP."""

    hidden: tuple[int, ...] = (64, 64)
    lr: float = 2e-3
    features: int = 128
    """Columns of B: the MLP sees 2 x features inputs (cos and sin)."""
    sigma: float = 2.0
    """Standard deviation of B's entries on x and y (inputs lie in (-1, 1)): the bandwidth
    the network starts with, in cycles per unit of the normalised coordinates."""
    frequency_sigma: float | None = None
    """Standard deviation of B's entries on f (multi mode); None: ``sigma``."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.features >= 1, "features", f"must be >= 1, got {self.features}")
        require(self.sigma > 0, "sigma", f"must be > 0, got {self.sigma}")
        require(self.frequency_sigma is None or self.frequency_sigma > 0, "frequency_sigma",
                f"must be > 0 (or null: sigma), got {self.frequency_sigma}")

    def network_shapes(self, shape: FieldShape) -> dict[str, tuple[int, ...]]:
        """B (fixed), then the ReLU MLP on the 2 x features features."""
        return {"features.B": (shape.in_dim, self.features),
                **mlp_shapes([2 * self.features, *self.hidden, shape.out_dim], "mlp.")}


@dataclass(frozen=True)
class WireFieldConfig(NeuralFieldConfig):
    """WIRE (Saragadam et al. 2023): complex Gabor wavelet activations, complex output."""

    hidden: tuple[int, ...] = (48, 48)
    """Widths of the hidden layers, in complex units (each holds two real numbers)."""
    lr: float = 2e-3
    omega0: float = 10.0
    """omega0 of psi: the frequency of the wavelet's oscillation."""
    scale0: float = 5.0
    """s0 of psi: the inverse width of the wavelet's Gaussian envelope."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.omega0 > 0, "omega0", f"must be > 0, got {self.omega0}")
        require(self.scale0 >= 0, "scale0", f"must be >= 0, got {self.scale0}")

    def network_shapes(self, shape: FieldShape) -> dict[str, tuple[int, ...]]:
        """A real first layer, then complex layers stored as (re, im) pairs."""
        shapes = mlp_shapes(wire_widths(self, shape))
        return {name: (size if name.startswith("layers.0.") else (2, *size))
                for name, size in shapes.items()}


@dataclass(frozen=True)
class FinerFieldConfig(NeuralFieldConfig):
    """FINER (Liu et al. 2024): sin(omega0 (|z| + 1) z) activations, SIREN's weights."""

    hidden: tuple[int, ...] = (64, 64, 64)
    lr: float = 2e-3
    omega0_first: float = 15.0
    """omega0 of the first layer."""
    omega0_hidden: float = 30.0
    """omega0 of the hidden layers."""
    first_bias_scale: float = 1.0
    """k: the first layer's biases start U(-k, k); larger k widens the set of
    frequencies the network starts with (Liu et al. sec. 3.3)."""
    scale_gradient: bool = False
    """Differentiate through the period factor |z| + 1 too (off, as in the authors' code:
    the factor is treated as a constant in the gradient)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.omega0_first > 0, "omega0_first", f"must be > 0, got {self.omega0_first}")
        require(self.omega0_hidden > 0, "omega0_hidden",
                f"must be > 0, got {self.omega0_hidden}")
        require(self.first_bias_scale >= 0, "first_bias_scale",
                f"must be >= 0, got {self.first_bias_scale}")


@dataclass(frozen=True)
class HashGridFieldConfig(NeuralFieldConfig):
    """A multiresolution hash-grid encoding (Mueller et al. 2022), then a ReLU MLP."""

    hidden: tuple[int, ...] = (64, 64)
    lr: float = 1e-2
    levels: int = 8
    """L, the grid resolutions (geometric from ``base_resolution`` to the finest)."""
    features_per_level: int = 2
    """F, trained features per grid vertex."""
    log2_table_size: int = 14
    """log2 T: a level with more than T vertices hashes them into T table rows."""
    base_resolution: int = 4
    """N_min, cells per axis of the coarsest grid."""
    finest_resolution: int = 0
    """N_max, cells per axis of the finest grid; 0: the training grid's larger side."""
    encode_frequency: bool = True
    """Multi mode: the grid spans (x, y, f); off: it spans (x, y) and f goes to the MLP as
    it is."""
    init_scale: float = 1e-4
    """Table entries start U(-init_scale, init_scale)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(1 <= self.levels <= 32, "levels", f"must be in [1, 32], got {self.levels}")
        require(1 <= self.features_per_level <= 16, "features_per_level",
                f"must be in [1, 16], got {self.features_per_level}")
        require(4 <= self.log2_table_size <= 24, "log2_table_size",
                f"must be in [4, 24], got {self.log2_table_size}")
        require(self.base_resolution >= 1, "base_resolution",
                f"must be >= 1, got {self.base_resolution}")
        require(self.finest_resolution == 0 or self.finest_resolution >= self.base_resolution,
                "finest_resolution", f"must be 0 (the training grid) or >= base_resolution "
                f"({self.base_resolution}), got {self.finest_resolution}")
        require(self.init_scale >= 0, "init_scale", f"must be >= 0, got {self.init_scale}")

    def network_shapes(self, shape: FieldShape) -> dict[str, tuple[int, ...]]:
        """The tables of every level (:func:`hash_grid_layout`), then the ReLU MLP."""
        layout = hash_grid_layout(self, shape)
        tables = {f"encoding.tables.{level}": (rows, layout.features)
                  for level, rows in enumerate(layout.table_sizes)}
        return {**tables, **mlp_shapes([layout.encoded_dim, *self.hidden, shape.out_dim],
                                       "mlp.")}


# --------------------------------------------------------------------------- layouts
@dataclass(frozen=True)
class HashGridLayout:
    """A hash grid resolved against the data: its axes, resolutions and table sizes."""

    dims: int
    """Grid axes: 2 (x, y) or 3 (x, y, f)."""
    resolutions: tuple[int, ...]
    """N_l, cells per axis of each level."""
    table_sizes: tuple[int, ...]
    """Rows of each level's table: min(T, (N_l + 1)^dims)."""
    features: int
    raw_inputs: int
    """Input columns passed to the MLP as they are (f, when the grid spans only x, y)."""

    @property
    def hashed(self) -> tuple[bool, ...]:
        """Whether each level hashes its vertices (more vertices than table rows)."""
        return tuple((n + 1) ** self.dims > t for n, t in zip(self.resolutions,
                                                              self.table_sizes, strict=True))

    @property
    def encoded_dim(self) -> int:
        """Columns the MLP sees: L x F features plus the raw inputs."""
        return len(self.resolutions) * self.features + self.raw_inputs


def hash_grid_layout(config: HashGridFieldConfig, shape: FieldShape) -> HashGridLayout:
    """Levels N_l = floor(N_min b^l), b = (N_max / N_min)^(1 / (L - 1)) (Mueller et al. eq. 3).

    Raises :class:`FitError` when the finest resolution follows a grid not yet seen.
    """
    finest = config.finest_resolution
    if not finest:
        if shape.grid_shape is None:
            raise FitError("model: the hash grid's finest resolution follows the training "
                           "grid; the network is known after fit or load")
        finest = max(config.base_resolution, *shape.grid_shape)
    multi = FieldMode(shape.mode) == FieldMode.multi
    dims = 3 if multi and config.encode_frequency else 2
    levels = config.levels
    growth = (finest / config.base_resolution) ** (1.0 / (levels - 1)) if levels > 1 else 1.0
    resolutions = tuple(int(math.floor(config.base_resolution * growth ** level + 1e-9))
                        for level in range(levels))
    size = 2 ** config.log2_table_size
    tables = tuple(min(size, (n + 1) ** dims) for n in resolutions)
    return HashGridLayout(dims, resolutions, tables, config.features_per_level,
                          raw_inputs=shape.in_dim - dims)


def wire_widths(config: WireFieldConfig, shape: FieldShape) -> list[int]:
    """Widths input -> hidden ... -> 1 (the complex output) of a WIRE network."""
    return [shape.in_dim, *config.hidden, 1]


# --------------------------------------------------------------------------- initial weights
def _linear(rng: np.random.Generator, lead: tuple[int, ...], fan_in: int, fan_out: int,
            bound: float, bias_bound: float) -> tuple[np.ndarray, np.ndarray]:
    w = rng.uniform(-bound, bound, (*lead, fan_in, fan_out))
    b = rng.uniform(-bias_bound, bias_bound, (*lead, fan_out))
    return w.astype(np.float32), b.astype(np.float32)


def relu_mlp_state(rng: np.random.Generator, lead: tuple[int, ...], dims: list[int],
                   prefix: str) -> dict[str, np.ndarray]:
    """A ReLU MLP ``dims[0] -> ... -> dims[-1]``: He-uniform hidden layers, a Glorot-uniform
    output layer, zero biases; arrays ``<prefix>layers.<i>.weight`` / ``.bias``."""
    state = {}
    for i, (n_in, n_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        last = i == len(dims) - 2
        bound = math.sqrt(6.0 / (n_in + n_out)) if last else math.sqrt(6.0 / n_in)
        w, b = _linear(rng, lead, n_in, n_out, bound, 0.0)
        state[f"{prefix}layers.{i}.weight"], state[f"{prefix}layers.{i}.bias"] = w, b
    return state


def fourier_state(config: FourierFieldConfig, shape: FieldShape, rng: np.random.Generator,
                  lead: tuple[int, ...]) -> dict[str, np.ndarray]:
    """``features.B`` (in_dim, features), N(0, sigma^2) on x, y and N(0, frequency_sigma^2)
    on f, and the MLP ``mlp.layers.*``."""
    sigmas = np.full(shape.in_dim, config.sigma)
    if shape.in_dim == 3 and config.frequency_sigma is not None:
        sigmas[2] = config.frequency_sigma
    b = rng.standard_normal((*lead, shape.in_dim, config.features)) * sigmas[:, None]
    dims = [2 * config.features, *config.hidden, shape.out_dim]
    return {"features.B": b.astype(np.float32), **relu_mlp_state(rng, lead, dims, "mlp.")}


def finer_state(config: FinerFieldConfig, shape: FieldShape, rng: np.random.Generator,
                lead: tuple[int, ...]) -> dict[str, np.ndarray]:
    """SIREN's weights (first layer U(-1/n, 1/n), later U(-sqrt(6/n)/omega0, ...)); biases
    U(-1/sqrt(n), 1/sqrt(n)), the first layer's U(-k, k) (Liu et al.)."""
    dims = [shape.in_dim, *config.hidden, shape.out_dim]
    state = {}
    for i, (n_in, n_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        first = i == 0
        bound = 1.0 / n_in if first else math.sqrt(6.0 / n_in) / config.omega0_hidden
        bias = config.first_bias_scale if first else 1.0 / math.sqrt(n_in)
        state[f"layers.{i}.weight"], state[f"layers.{i}.bias"] = _linear(
            rng, lead, n_in, n_out, bound, bias)
    return state


def wire_state(config: WireFieldConfig, shape: FieldShape, rng: np.random.Generator,
               lead: tuple[int, ...]) -> dict[str, np.ndarray]:
    """A real first layer, then complex layers whose weights (2, fan_in, fan_out) and biases
    (2, fan_out) hold (re, im); every value U(-1/sqrt(fan_in), 1/sqrt(fan_in)) (PyTorch's
    default for linear layers, as in the authors' code)."""
    dims = wire_widths(config, shape)
    state = {}
    for i, (n_in, n_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        bound = 1.0 / math.sqrt(n_in)
        parts = () if i == 0 else (2,)
        w = rng.uniform(-bound, bound, (*lead, *parts, n_in, n_out))
        b = rng.uniform(-bound, bound, (*lead, *parts, n_out))
        state[f"layers.{i}.weight"] = w.astype(np.float32)
        state[f"layers.{i}.bias"] = b.astype(np.float32)
    return state


def hashgrid_state(config: HashGridFieldConfig, shape: FieldShape, rng: np.random.Generator,
                   lead: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Tables ``encoding.tables.<l>`` (rows, F) U(-init_scale, init_scale), then the MLP."""
    layout = hash_grid_layout(config, shape)
    s = config.init_scale
    state = {f"encoding.tables.{level}": rng.uniform(-s, s, (*lead, rows, layout.features))
             .astype(np.float32) for level, rows in enumerate(layout.table_sizes)}
    dims = [layout.encoded_dim, *config.hidden, shape.out_dim]
    return {**state, **relu_mlp_state(rng, lead, dims, "mlp.")}


_STATES: dict[type, Callable[..., dict[str, np.ndarray]]] = {
    FourierFieldConfig: fourier_state,
    WireFieldConfig: wire_state,
    FinerFieldConfig: finer_state,
    HashGridFieldConfig: hashgrid_state,
}


def field_network_state(config: NeuralFieldConfig, shape: FieldShape, n_networks: int, seed: int
                  ) -> dict[str, np.ndarray]:
    """The initial arrays (float32, by name) of the network ``config`` configures; with
    ``n_networks`` > 0 each gets a leading axis of that length (single mode)."""
    rng = np.random.default_rng([int(seed), 0x696E72])  # "inr" stream
    lead = (n_networks,) if n_networks > 0 else ()
    for cls, state in _STATES.items():
        if isinstance(config, cls):
            return dict(state(config, shape, rng, lead))
    valid = ", ".join(c.__name__ for c in _STATES)
    raise DataError(f"model: {type(config).__name__} configures none of the networks "
                    f"fourier, wire, finer, hashgrid; valid: {valid}")


# --------------------------------------------------------------------------- registration
@dataclass(frozen=True)
class FieldNetwork:
    """How the torch and JAX plugins register one of these networks."""

    config: type[NeuralFieldConfig]
    description: str
    test_config: Mapping[str, object]
    """Small, fast options for the conformance kit."""


_TEST = {"steps": 300, "batch_size": 0, "eval_every": 50, "validation_fraction": 0.0}

#: The four networks, by registered name (each engine appends ``_torch`` / ``_jax``).
FIELD_NETWORKS: dict[str, FieldNetwork] = {
    "fourier": FieldNetwork(FourierFieldConfig, "Fourier-feature MLP (Tancik et al. 2020)",
                            {**_TEST, "hidden": [32, 32], "features": 32, "sigma": 0.5,
                             "lr": 1e-2}),
    "wire": FieldNetwork(WireFieldConfig, "WIRE: complex Gabor wavelet activations, complex "
                         "output (Saragadam et al. 2023)",
                         {**_TEST, "hidden": [24, 24], "omega0": 5.0, "scale0": 2.0,
                          "lr": 5e-3}),
    "finer": FieldNetwork(FinerFieldConfig, "FINER: variable-periodic sin((|z|+1) z) "
                          "activations (Liu et al. 2024)",
                          {**_TEST, "hidden": [32, 32], "lr": 2e-3}),
    "hashgrid": FieldNetwork(HashGridFieldConfig, "Multiresolution hash-grid encoding and a "
                             "small MLP (Mueller et al. 2022), plain torch/JAX",
                             {**_TEST, "hidden": [32], "levels": 4, "base_resolution": 2,
                              "finest_resolution": 8, "lr": 1e-2}),
}

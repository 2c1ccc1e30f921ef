"""Two neural fields whose inputs are encoded before an MLP, backend-neutral: options,
layout and initial weights.

* ``fourier`` (Tancik et al. 2020): features [cos 2 pi v B, sin 2 pi v B] of the inputs v
  with a fixed Gaussian matrix B (entries N(0, sigma^2)), then a ReLU MLP.
* ``hashgrid`` (Mueller et al. 2022): a multiresolution hash-grid encoding of (x, y)
  (and of f in multi mode, unless ``encode_frequency`` is off), d-linear interpolation
  of trained feature tables, then a small ReLU MLP.

The torch and JAX plugins build the same modules (``nlosfw_torch.networks``,
``nlosfw_jax.networks``); both start from the numpy weights of
:func:`~nlosfw.model.neural.catalogue.field_network_state`, so the two backends train the
same network and read each other's files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import require
from nlosfw.common.errors import FitError
from nlosfw.model.neural.config import FieldMode, FieldShape, NeuralFieldConfig, mlp_shapes
from nlosfw.model.neural.mlp import uniform_layer

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

    def activation_widths(self) -> int:
        """The hidden layers and the 2 x features features."""
        return sum(self.hidden) + 2 * self.features


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


# --------------------------------------------------------------------------- initial weights
def relu_mlp_state(rng: np.random.Generator, lead: tuple[int, ...], dims: list[int],
                   prefix: str) -> dict[str, np.ndarray]:
    """A ReLU MLP ``dims[0] -> ... -> dims[-1]``: He-uniform hidden layers, a Glorot-uniform
    output layer, zero biases; arrays ``<prefix>layers.<i>.weight`` / ``.bias``."""
    state = {}
    for i, (n_in, n_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        last = i == len(dims) - 2
        bound = math.sqrt(6.0 / (n_in + n_out)) if last else math.sqrt(6.0 / n_in)
        w, b = uniform_layer(rng, lead, n_in, n_out, bound, 0.0)
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


def hashgrid_state(config: HashGridFieldConfig, shape: FieldShape, rng: np.random.Generator,
                   lead: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Tables ``encoding.tables.<l>`` (rows, F) U(-init_scale, init_scale), then the MLP."""
    layout = hash_grid_layout(config, shape)
    s = config.init_scale
    state = {f"encoding.tables.{level}": rng.uniform(-s, s, (*lead, rows, layout.features))
             .astype(np.float32) for level, rows in enumerate(layout.table_sizes)}
    dims = [layout.encoded_dim, *config.hidden, shape.out_dim]
    return {**state, **relu_mlp_state(rng, lead, dims, "mlp.")}

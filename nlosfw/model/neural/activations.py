"""Two neural fields with periodic or wavelet activations, backend-neutral: options and
initial weights.

* ``wire`` (Saragadam et al. 2023): complex Gabor wavelet activations
  psi(z) = exp(i omega0 z - |s0 z|^2); the first layer is real, the later ones complex,
  and the network outputs the complex phasor itself.
* ``finer`` (Liu et al. 2024): the variable-periodic activation sin(omega0 (|z| + 1) z)
  with SIREN's weights and a wide first-layer bias U(-k, k).

As for :mod:`nlosfw.model.neural.encodings`, the torch and JAX plugins build the same
modules from the same numpy weights. Weights are stored as real arrays (a complex weight
as a leading axis (re, im)), so parameter counts are counts of real numbers and Adam sees
the same values in both backends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import require
from nlosfw.model.neural.config import FieldShape, NeuralFieldConfig, mlp_shapes
from nlosfw.model.neural.mlp import uniform_layer


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


def wire_widths(config: WireFieldConfig, shape: FieldShape) -> list[int]:
    """Widths input -> hidden ... -> 1 (the complex output) of a WIRE network."""
    return [shape.in_dim, *config.hidden, 1]


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
        state[f"layers.{i}.weight"], state[f"layers.{i}.bias"] = uniform_layer(
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

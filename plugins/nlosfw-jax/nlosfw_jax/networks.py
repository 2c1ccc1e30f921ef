"""Equinox parts networks are built from, the thesis networks (tanh, PE, SIREN) and
the networks with an encoded input or periodic activations (fourier, wire, finer,
hashgrid).

Parts: :class:`Linear` (weights (fan_in, fan_out), the layout the numpy reference
and the torch plugin share, so their files load across backends), :class:`Sine`,
:class:`PositionalEncoding`, :class:`MLP`, :class:`FourierFeatures`, :class:`Finer`,
:class:`ComplexLinear`, :class:`Gabor` and :class:`HashGridEncoding`. The factories
:func:`thesis_network` and :func:`field_network` build the networks for the shared
trainer; they start from backend-neutral numpy weights
(:func:`nlosfw.model.neural.reference_state`, :func:`nlosfw.model.neural.field_network_state`), so
JAX and torch train the same network.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nlosfw.model import NeuralFieldConfig
from nlosfw.model.neural import (
    HASH_PRIMES,
    Architecture,
    FieldShape,
    FinerFieldConfig,
    FourierFieldConfig,
    HashGridFieldConfig,
    HashGridLayout,
    WireFieldConfig,
    field_network_state,
    hash_grid_layout,
    reference_state,
    thesis_architecture,
    wire_widths,
)
from nlosfw_jax.backend import Fixed

#: An activation: a function (or parameter-free module) of one array.
Activation = Callable[[jax.Array], jax.Array]

#: Odd polynomial for sin on [-pi/2, pi/2] (Taylor-minimax, float32 accuracy).
_SIN_COEFFS = (1.0, -1.6666667163e-01, 8.3333337680e-03, -1.9841270114e-04, 2.7557314297e-06,
               -2.5050759689e-08, 1.5896910177e-10)


def fast_sin(v: jax.Array) -> jax.Array:
    """sin(v) within 2e-7 for |v| < 1000, about three times faster than ``jnp.sin`` on CPU.

    XLA's CPU sine dominated SIREN training time; this reduces v by multiples of pi
    (pi split in two parts) and evaluates an odd polynomial, in plain fused arithmetic.
    """
    k = jnp.round(v * (1.0 / np.pi))
    r = v - k * 3.140625 - k * 9.676535897932795e-4
    r2 = r * r
    p = jnp.full_like(r, _SIN_COEFFS[-1])
    for c in _SIN_COEFFS[-2::-1]:
        p = p * r2 + c
    odd = jnp.bitwise_and(k.astype(jnp.int32), 1)
    return r * p * (1 - 2 * odd).astype(r.dtype)


class Linear(eqx.Module):
    """x W + b with ``weight`` W of shape (fan_in, fan_out), Glorot-uniform, zero bias."""

    weight: jax.Array
    bias: jax.Array

    def __init__(self, fan_in: int, fan_out: int, key: jax.Array) -> None:
        bound = float(np.sqrt(6.0 / (fan_in + fan_out)))
        self.weight = jax.random.uniform(key, (fan_in, fan_out), minval=-bound, maxval=bound)
        self.bias = jnp.zeros(fan_out)

    def __call__(self, x: jax.Array) -> jax.Array:
        return jnp.matmul(x, self.weight) + self.bias


class Sine(eqx.Module):
    """sin(omega0 z), SIREN's activation."""

    omega0: float = eqx.field(static=True)

    def __call__(self, z: jax.Array) -> jax.Array:
        return fast_sin(self.omega0 * z)


class Tanh(eqx.Module):
    """tanh(z)."""

    def __call__(self, z: jax.Array) -> jax.Array:
        return jnp.tanh(z)


class ReLU(eqx.Module):
    """max(z, 0)."""

    def __call__(self, z: jax.Array) -> jax.Array:
        return jax.nn.relu(z)


class PositionalEncoding(eqx.Module):
    """NeRF's gamma of every column u of (N, D): sin(2^l pi u), cos(2^l pi u) for l < L,
    per column (thesis eq. 4.3) -> (N, 2 D L)."""

    octaves: int = eqx.field(static=True)

    def __call__(self, u: jax.Array) -> jax.Array:
        scales = jnp.pi * 2.0 ** jnp.arange(self.octaves, dtype=u.dtype)
        arg = u[..., None] * scales                                    # (N, D, L)
        return jnp.stack([jnp.sin(arg), jnp.cos(arg)], axis=-1).reshape(u.shape[0], -1)


class MLP(eqx.Module):
    """Linear layers ``dims[0] -> ... -> dims[-1]``, ``activations[i]`` after hidden layer i."""

    layers: list[Linear]
    activations: list[Activation]

    def __init__(self, dims: Sequence[int], activations: Sequence[Activation],
                 key: jax.Array) -> None:
        if len(activations) != len(dims) - 2:
            raise ValueError(f"{len(dims) - 2} hidden layers need as many activations")
        keys = jax.random.split(key, len(dims) - 1)
        self.layers = [Linear(a, b, k) for a, b, k in zip(dims[:-1], dims[1:], keys,
                                                          strict=True)]
        self.activations = list(activations)

    def __call__(self, h: jax.Array) -> jax.Array:
        for layer, activation in zip(self.layers[:-1], self.activations, strict=True):
            h = activation(layer(h))
        return self.layers[-1](h)


class ThesisInputs(eqx.Module):
    """The thesis networks' input features from (x, y[, f]): as they are, or PE's
    gamma(x, y) (plus x, y with ``include_input``) and f raw or gamma(f)."""

    arch: Architecture = eqx.field(static=True)

    def __call__(self, x: jax.Array) -> jax.Array:
        arch = self.arch
        if arch.family != "pe":
            return x
        xy, f = x[:, :2], x[:, 2:]
        parts = [PositionalEncoding(arch.octaves)(xy), *([xy] if arch.include_input else [])]
        if f.shape[1]:
            encoded = arch.frequency_input == "encoded"
            parts.append(PositionalEncoding(arch.frequency_octaves)(f) if encoded else f)
        return jnp.concatenate(parts, axis=1)


class ThesisNetwork(MLP):
    """A thesis network: :class:`ThesisInputs`, then the :class:`MLP` of ``arch``."""

    inputs: ThesisInputs
    arch: Architecture = eqx.field(static=True)

    def __init__(self, arch: Architecture, key: jax.Array) -> None:
        n_hidden = len(arch.hidden)
        acts: list[Activation]
        if arch.activation == "sine":
            acts = [Sine(arch.omega0_first if i == 0 else arch.omega0_hidden)
                    for i in range(n_hidden)]
        else:
            acts = [ReLU() if arch.activation == "relu" else Tanh() for _ in range(n_hidden)]
        super().__init__([arch.in_dim, *arch.hidden, arch.out_dim], acts, key)
        self.inputs = ThesisInputs(arch)
        self.arch = arch

    def __call__(self, x: jax.Array) -> jax.Array:
        return super().__call__(self.inputs(x))

    def initial_state(self, n_networks: int, seed: int) -> dict[str, np.ndarray]:
        """The backend-neutral initial weights (see :func:`nlosfw.model.neural.init_parameters`)."""
        return reference_state(self.arch, n_networks, seed)


def thesis_network(config: NeuralFieldConfig, shape: FieldShape, key: jax.Array
                   ) -> ThesisNetwork:
    """The factory of tanh, pe and siren: the network of ``config``'s class, for ``shape``."""
    return ThesisNetwork(thesis_architecture(config, shape), key)


# ------------------------------------------------ encodings' and activations' parts
class FourierFeatures(eqx.Module):
    """[cos 2 pi v B, sin 2 pi v B] of inputs v (N, D), B (D, features) fixed."""

    B: Fixed

    def __init__(self, in_dim: int, features: int) -> None:
        self.B = Fixed(jnp.zeros((in_dim, features)))

    def __call__(self, v: jax.Array) -> jax.Array:
        angle = 2 * jnp.pi * (v @ self.B.value)
        return jnp.concatenate([fast_sin(angle + np.pi / 2), fast_sin(angle)], axis=-1)


class Finer(eqx.Module):
    """FINER's sin(omega0 (|z| + 1) z); the factor |z| + 1 is a constant to the gradient
    unless ``scale_gradient``."""

    omega0: float = eqx.field(static=True)
    scale_gradient: bool = eqx.field(static=True, default=False)

    def __call__(self, z: jax.Array) -> jax.Array:
        scale = jnp.abs(z) + 1
        return fast_sin(self.omega0 * (scale if self.scale_gradient
                                       else jax.lax.stop_gradient(scale)) * z)


class ComplexLinear(eqx.Module):
    """The complex map z W + b on real pairs: [Re z, Im z] (N, 2 fan_in) -> [Re, Im]
    (N, 2 fan_out), with W = weight[0] + i weight[1] (fan_in, fan_out), b = bias[0] + i bias[1]."""

    weight: jax.Array
    bias: jax.Array

    def __init__(self, fan_in: int, fan_out: int) -> None:
        self.weight = jnp.zeros((2, fan_in, fan_out))
        self.bias = jnp.zeros((2, fan_out))

    def __call__(self, h: jax.Array) -> jax.Array:
        re, im = self.weight[0], self.weight[1]
        matrix = jnp.concatenate([jnp.concatenate([re, im], 1), jnp.concatenate([-im, re], 1)])
        return h @ matrix + self.bias.reshape(-1)


class Gabor(eqx.Module):
    """WIRE's complex Gabor wavelet psi(z) = exp(i omega0 z - |s0 z|^2) of z = re + i im
    (im None: z real), as real pairs [Re psi, Im psi]."""

    omega0: float = eqx.field(static=True)
    scale0: float = eqx.field(static=True)

    def __call__(self, re: jax.Array, im: jax.Array | None = None) -> jax.Array:
        size = jnp.square(re) if im is None else jnp.square(re) + jnp.square(im)
        log_envelope = -self.scale0 ** 2 * size - (0 if im is None else self.omega0 * im)
        envelope, phase = jnp.exp(log_envelope), self.omega0 * re
        return jnp.concatenate([envelope * fast_sin(phase + np.pi / 2),
                                envelope * fast_sin(phase)], axis=-1)


class HashGridEncoding(eqx.Module):
    """Multiresolution hash-grid features of the first ``layout.dims`` input columns (in
    (-1, 1), clamped), d-linearly interpolated per level; other columns are appended."""

    tables: list[jax.Array]
    layout: HashGridLayout = eqx.field(static=True)

    def __init__(self, layout: HashGridLayout) -> None:
        self.layout = layout
        self.tables = [jnp.zeros((rows, layout.features)) for rows in layout.table_sizes]

    def __call__(self, x: jax.Array) -> jax.Array:
        d, out = self.layout.dims, []
        corners = np.array(list(itertools.product((0, 1), repeat=d)))      # (2^d, d)
        u = jnp.clip((x[:, :d] + 1) / 2, 0, 1)
        for n, table in zip(self.layout.resolutions, self.tables, strict=True):
            cell = jnp.minimum(jnp.floor(u * n), n - 1)
            frac = (u * n - cell)[:, None, :]                              # (N, 1, d)
            vertex = cell.astype(jnp.uint32)[:, None, :] + corners.astype(np.uint32)
            weight = jnp.where(corners.astype(bool), frac, 1 - frac).prod(-1)
            row = self._row(vertex, n, table.shape[0])
            out.append((weight[..., None] * jnp.take(table, row, axis=0)).sum(1))
        return jnp.concatenate([*out, x[:, d:]], axis=1)

    def _row(self, vertex: jax.Array, n: int, rows: int) -> jax.Array:
        """Table rows of grid vertices (..., d): row-major when every vertex has its own row,
        else the spatial hash (XOR of coordinate x prime, uint32) mod ``rows`` (a power of 2)."""
        dense = (n + 1) ** self.layout.dims <= rows
        row = vertex[..., 0] * np.uint32(HASH_PRIMES[0])
        for axis in range(1, self.layout.dims):
            if dense:
                row = row + vertex[..., axis] * np.uint32((n + 1) ** axis)
            else:
                row = jnp.bitwise_xor(row, vertex[..., axis] * np.uint32(HASH_PRIMES[axis]))
        return (row if dense else jnp.bitwise_and(row, np.uint32(rows - 1))).astype(jnp.int32)


# --------------------------------------- networks with encodings or periodic activations
class _FromNumpy(eqx.Module):
    """A network whose initial weights are :func:`nlosfw.model.neural.field_network_state`'s."""

    config: NeuralFieldConfig = eqx.field(static=True)
    shape: FieldShape = eqx.field(static=True)

    def initial_state(self, n_networks: int, seed: int) -> dict[str, np.ndarray]:
        return field_network_state(self.config, self.shape, n_networks, seed)


class FourierNetwork(_FromNumpy):
    """:class:`FourierFeatures`, then a ReLU :class:`MLP`."""

    features: FourierFeatures
    mlp: MLP

    def __init__(self, config: FourierFieldConfig, shape: FieldShape, key: jax.Array) -> None:
        self.config, self.shape = config, shape
        self.features = FourierFeatures(shape.in_dim, config.features)
        self.mlp = MLP([2 * config.features, *config.hidden, shape.out_dim],
                       [ReLU() for _ in config.hidden], key)

    def __call__(self, v: jax.Array) -> jax.Array:
        return self.mlp(self.features(v))


class FinerNetwork(MLP):
    """An :class:`MLP` with :class:`Finer` activations."""

    config: FinerFieldConfig = eqx.field(static=True)
    shape: FieldShape = eqx.field(static=True)

    def __init__(self, config: FinerFieldConfig, shape: FieldShape, key: jax.Array) -> None:
        acts = [Finer(config.omega0_first if i == 0 else config.omega0_hidden,
                      config.scale_gradient) for i in range(len(config.hidden))]
        super().__init__([shape.in_dim, *config.hidden, shape.out_dim], acts, key)
        self.config, self.shape = config, shape

    def initial_state(self, n_networks: int, seed: int) -> dict[str, np.ndarray]:
        return field_network_state(self.config, self.shape, n_networks, seed)


class WireNetwork(_FromNumpy):
    """A real :class:`Linear`, then :class:`ComplexLinear` layers, :class:`Gabor` after each
    but the last; returns the complex field (N,) itself."""

    layers: list[Any]
    gabor: Gabor

    def __init__(self, config: WireFieldConfig, shape: FieldShape, key: jax.Array) -> None:
        self.config, self.shape = config, shape
        dims = wire_widths(config, shape)
        self.layers = [Linear(dims[0], dims[1], key), *(
            ComplexLinear(a, b) for a, b in zip(dims[1:-1], dims[2:], strict=True))]
        self.gabor = Gabor(config.omega0, config.scale0)

    def __call__(self, v: jax.Array) -> jax.Array:
        h = self.gabor(self.layers[0](v))                  # real first layer
        for layer in self.layers[1:-1]:
            re, im = jnp.split(layer(h), 2, axis=-1)
            h = self.gabor(re, im)
        out = self.layers[-1](h)                           # [Re, Im] of the one output
        return jax.lax.complex(out[:, 0], out[:, 1])


class HashGridNetwork(_FromNumpy):
    """A :class:`HashGridEncoding`, then a ReLU :class:`MLP`."""

    encoding: HashGridEncoding
    mlp: MLP

    def __init__(self, config: HashGridFieldConfig, shape: FieldShape, key: jax.Array) -> None:
        self.config, self.shape = config, shape
        layout = hash_grid_layout(config, shape)
        self.encoding = HashGridEncoding(layout)
        self.mlp = MLP([layout.encoded_dim, *config.hidden, shape.out_dim],
                       [ReLU() for _ in config.hidden], key)

    def __call__(self, v: jax.Array) -> jax.Array:
        return self.mlp(self.encoding(v))


_NETWORKS: dict[type, Any] = {FourierFieldConfig: FourierNetwork, WireFieldConfig: WireNetwork,
                              FinerFieldConfig: FinerNetwork, HashGridFieldConfig: HashGridNetwork}


def field_network(config: NeuralFieldConfig, shape: FieldShape, key: jax.Array) -> eqx.Module:
    """The factory of fourier, wire, finer and hashgrid: the network of ``config``'s class."""
    for cls, network in _NETWORKS.items():
        if isinstance(config, cls):
            return network(config, shape, key)
    raise TypeError(f"{type(config).__name__} configures none of fourier, wire, finer, hashgrid")

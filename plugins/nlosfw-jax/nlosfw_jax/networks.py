"""Equinox parts networks are built from, and the thesis networks (tanh, PE, SIREN).

Parts: :class:`Linear` (weights (fan_in, fan_out), the layout the numpy reference
and the torch plugin share, so their files load across backends), :class:`Sine`,
:class:`PositionalEncoding` and :class:`MLP`. The factory :func:`thesis_network`
builds the thesis networks for the shared trainer; they start from the
backend-neutral weights of :func:`nlosfw.model.reference_state`, so JAX and torch
train the same network.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from nlosfw.model import (
    Architecture,
    FieldShape,
    NeuralFieldConfig,
    reference_state,
    thesis_architecture,
)

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
        """The backend-neutral initial weights (see :func:`nlosfw.model.init_parameters`)."""
        return reference_state(self.arch, n_networks, seed)


def thesis_network(config: NeuralFieldConfig, shape: FieldShape, key: jax.Array
                   ) -> ThesisNetwork:
    """The factory of tanh, pe and siren: the network of ``config``'s class, for ``shape``."""
    return ThesisNetwork(thesis_architecture(config, shape), key)

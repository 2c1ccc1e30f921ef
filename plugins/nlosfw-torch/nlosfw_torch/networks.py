"""Torch parts networks are built from, the thesis networks (tanh, PE, SIREN) and
the networks with an encoded input or periodic activations (fourier, wire, finer,
hashgrid).

Parts: :class:`Linear` (weights (fan_in, fan_out), the layout the numpy reference
and the JAX plugin share), :class:`Sine` (sin(omega0 z)), :class:`PositionalEncoding`
(NeRF's gamma), :class:`MLP` (linear layers with an activation after each hidden
one), :class:`FourierFeatures`, :class:`Finer`, :class:`ComplexLinear`,
:class:`Gabor`, and the hash grid's encoding
(:class:`~nlosfw_torch.hash_grid.HashGridEncoding`). The factories
:func:`thesis_network` and :func:`field_network` build the networks for the shared
trainer; they start from backend-neutral numpy weights
(:func:`nlosfw.model.neural.reference_state`, :func:`nlosfw.model.neural.field_network_state`), so
torch and JAX train the same network.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from nlosfw.model import NeuralFieldConfig
from nlosfw.model.neural import (
    Architecture,
    FieldShape,
    FinerFieldConfig,
    FourierFieldConfig,
    HashGridFieldConfig,
    WireFieldConfig,
    field_network_state,
    hash_grid_layout,
    reference_state,
    thesis_architecture,
    wire_widths,
)
from nlosfw_torch.hash_grid import CORNERS_MAX_BYTES, HashCorners, HashGridEncoding


class Linear(nn.Module):
    """x W + b with ``weight`` W of shape (fan_in, fan_out), Glorot-uniform, zero bias."""

    def __init__(self, fan_in: int, fan_out: int) -> None:
        super().__init__()
        bound = float(np.sqrt(6.0 / (fan_in + fan_out)))
        self.weight = nn.Parameter(torch.empty(fan_in, fan_out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.zeros(fan_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.addmm(self.bias, x, self.weight)


class Sine(nn.Module):
    """sin(omega0 z), SIREN's activation."""

    def __init__(self, omega0: float) -> None:
        super().__init__()
        self.omega0 = float(omega0)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return torch.sin(self.omega0 * z)


class PositionalEncoding(nn.Module):
    """NeRF's gamma of every column u of (N, D): sin(2^l pi u), cos(2^l pi u) for l < L,
    per column (thesis eq. 4.3) -> (N, 2 D L)."""

    def __init__(self, octaves: int) -> None:
        super().__init__()
        self.octaves = int(octaves)

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        scales = torch.pi * 2.0 ** torch.arange(self.octaves, dtype=u.dtype, device=u.device)
        arg = u[..., None] * scales                                    # (N, D, L)
        return torch.stack([torch.sin(arg), torch.cos(arg)], dim=-1).flatten(-3)


class MLP(nn.Module):
    """Linear layers ``dims[0] -> ... -> dims[-1]``, ``activations[i]`` after hidden layer i."""

    def __init__(self, dims: Sequence[int], activations: Sequence[nn.Module]) -> None:
        super().__init__()
        if len(activations) != len(dims) - 2:
            raise ValueError(f"{len(dims) - 2} hidden layers need as many activations")
        self.layers = nn.ModuleList(Linear(a, b) for a, b in zip(dims[:-1], dims[1:],
                                                                 strict=True))
        self.activations = nn.ModuleList(activations)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        for layer, activation in zip(self.layers[:-1], self.activations, strict=True):
            h = activation(layer(h))
        return self.layers[-1](h)


class ThesisInputs(nn.Module):
    """The thesis networks' input features from (x, y[, f]): as they are, or PE's
    gamma(x, y) (plus x, y with ``include_input``) and f raw or gamma(f)."""

    def __init__(self, arch: Architecture) -> None:
        super().__init__()
        self.arch = arch
        self.xy_encoding = PositionalEncoding(arch.octaves)
        self.f_encoding = PositionalEncoding(arch.frequency_octaves)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        arch = self.arch
        if arch.family != "pe":
            return x
        xy, f = x[:, :2], x[:, 2:]
        parts = [self.xy_encoding(xy), *([xy] if arch.include_input else [])]
        if f.shape[1]:
            parts.append(self.f_encoding(f) if arch.frequency_input == "encoded" else f)
        return torch.cat(parts, dim=1)


class ThesisNetwork(MLP):
    """A thesis network: :class:`ThesisInputs`, then the :class:`MLP` of ``arch``."""

    def __init__(self, arch: Architecture) -> None:
        n_hidden = len(arch.hidden)
        if arch.activation == "sine":
            acts: list[nn.Module] = [Sine(arch.omega0_first if i == 0 else arch.omega0_hidden)
                                     for i in range(n_hidden)]
        else:
            acts = [nn.ReLU() if arch.activation == "relu" else nn.Tanh()
                    for _ in range(n_hidden)]
        super().__init__([arch.in_dim, *arch.hidden, arch.out_dim], acts)
        self.arch = arch
        self.inputs = ThesisInputs(arch)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(self.inputs(x))

    def initial_state(self, n_networks: int, seed: int) -> dict[str, np.ndarray]:
        """The backend-neutral initial weights (see :func:`nlosfw.model.neural.init_parameters`)."""
        return reference_state(self.arch, n_networks, seed)


def thesis_network(config: NeuralFieldConfig, shape: FieldShape) -> ThesisNetwork:
    """The factory of tanh, pe and siren: the network of ``config``'s class, for ``shape``."""
    return ThesisNetwork(thesis_architecture(config, shape))


# ------------------------------------------------ encodings' and activations' parts
class FourierFeatures(nn.Module):
    """[cos 2 pi v B, sin 2 pi v B] of inputs v (N, D), B (D, features) a fixed buffer."""

    B: torch.Tensor

    def __init__(self, in_dim: int, features: int) -> None:
        super().__init__()
        self.register_buffer("B", torch.zeros(in_dim, features))

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        angle = 2 * math.pi * (v @ self.B)
        return torch.cat([torch.cos(angle), torch.sin(angle)], dim=-1)


class Finer(nn.Module):
    """FINER's sin(omega0 (|z| + 1) z); the factor |z| + 1 is a constant to the gradient
    unless ``scale_gradient``."""

    def __init__(self, omega0: float, scale_gradient: bool = False) -> None:
        super().__init__()
        self.omega0, self.scale_gradient = float(omega0), scale_gradient

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        scale = torch.abs(z) + 1
        return torch.sin(self.omega0 * (scale if self.scale_gradient else scale.detach()) * z)


class ComplexLinear(nn.Module):
    """The complex map z W + b on real pairs: [Re z, Im z] (N, 2 fan_in) -> [Re, Im]
    (N, 2 fan_out), with W = weight[0] + i weight[1] (fan_in, fan_out), b = bias[0] + i bias[1]
    (a real matrix product: torch's complex kernels are several times slower on CPU)."""

    def __init__(self, fan_in: int, fan_out: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(2, fan_in, fan_out))
        self.bias = nn.Parameter(torch.zeros(2, fan_out))

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        re, im = self.weight[0], self.weight[1]
        matrix = torch.cat([torch.cat([re, im], 1), torch.cat([-im, re], 1)], 0)
        return h @ matrix + self.bias.reshape(-1)


class Gabor(nn.Module):
    """WIRE's complex Gabor wavelet psi(z) = exp(i omega0 z - |s0 z|^2) of z = re + i im
    (im None: z real), as real pairs [Re psi, Im psi]."""

    def __init__(self, omega0: float, scale0: float) -> None:
        super().__init__()
        self.omega0, self.scale0 = float(omega0), float(scale0)

    def forward(self, re: torch.Tensor, im: torch.Tensor | None = None) -> torch.Tensor:
        size = torch.square(re) if im is None else torch.square(re) + torch.square(im)
        log_envelope = -self.scale0 ** 2 * size - (0 if im is None else self.omega0 * im)
        envelope, phase = torch.exp(log_envelope), self.omega0 * re
        return torch.cat([envelope * torch.cos(phase), envelope * torch.sin(phase)], dim=-1)


# --------------------------------------- networks with encodings or periodic activations
class _FromNumpy:
    """A network whose initial weights are :func:`nlosfw.model.neural.field_network_state`'s."""

    config: NeuralFieldConfig
    shape: FieldShape

    def initial_state(self, n_networks: int, seed: int) -> dict[str, np.ndarray]:
        return field_network_state(self.config, self.shape, n_networks, seed)


class FourierNetwork(_FromNumpy, nn.Module):
    """:class:`FourierFeatures`, then a ReLU :class:`MLP`."""

    def __init__(self, config: FourierFieldConfig, shape: FieldShape) -> None:
        super().__init__()
        self.config, self.shape = config, shape
        self.features = FourierFeatures(shape.in_dim, config.features)
        self.mlp = MLP([2 * config.features, *config.hidden, shape.out_dim],
                       [nn.ReLU() for _ in config.hidden])

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.features(v))


class FinerNetwork(_FromNumpy, MLP):
    """An :class:`MLP` with :class:`Finer` activations."""

    def __init__(self, config: FinerFieldConfig, shape: FieldShape) -> None:
        acts = [Finer(config.omega0_first if i == 0 else config.omega0_hidden,
                      config.scale_gradient) for i in range(len(config.hidden))]
        super().__init__([shape.in_dim, *config.hidden, shape.out_dim], acts)
        self.config, self.shape = config, shape


class WireNetwork(_FromNumpy, nn.Module):
    """A real :class:`Linear`, then :class:`ComplexLinear` layers, :class:`Gabor` after each
    but the last; returns the complex field (N,) itself."""

    def __init__(self, config: WireFieldConfig, shape: FieldShape) -> None:
        super().__init__()
        self.config, self.shape = config, shape
        dims = wire_widths(config, shape)
        self.layers = nn.ModuleList([Linear(dims[0], dims[1]), *(
            ComplexLinear(a, b) for a, b in zip(dims[1:-1], dims[2:], strict=True))])
        self.gabor = Gabor(config.omega0, config.scale0)

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        h = self.gabor(self.layers[0](v))                  # real first layer
        for layer in self.layers[1:-1]:
            re, im = layer(h).chunk(2, dim=-1)
            h = self.gabor(re, im)
        out = self.layers[-1](h)                           # [Re, Im] of the one output
        return torch.complex(out[:, 0], out[:, 1])


class HashGridNetwork(_FromNumpy, nn.Module):
    """A :class:`HashGridEncoding`, then a ReLU :class:`MLP`."""

    def __init__(self, config: HashGridFieldConfig, shape: FieldShape) -> None:
        super().__init__()
        self.config, self.shape = config, shape
        layout = hash_grid_layout(config, shape)
        self.encoding = HashGridEncoding(layout)
        self.mlp = MLP([layout.encoded_dim, *config.hidden, shape.out_dim],
                       [nn.ReLU() for _ in config.hidden])

    def forward(self, v: torch.Tensor | HashCorners) -> torch.Tensor:
        return self.mlp(self.encoding(v))

    def precompute_inputs(self, x: torch.Tensor) -> HashCorners | None:
        """The grid corners of fixed inputs ``x`` (N, D), to pass instead of them at every
        step (see :class:`HashCorners`); None when they would exceed
        :data:`~nlosfw_torch.hash_grid.CORNERS_MAX_BYTES`."""
        if self.encoding.corners_bytes(int(x.shape[0])) > CORNERS_MAX_BYTES:
            return None
        return self.encoding.corners(x)


_NETWORKS: dict[type, Any] = {FourierFieldConfig: FourierNetwork, WireFieldConfig: WireNetwork,
                              FinerFieldConfig: FinerNetwork, HashGridFieldConfig: HashGridNetwork}


def field_network(config: NeuralFieldConfig, shape: FieldShape) -> nn.Module:
    """The factory of fourier, wire, finer and hashgrid: the network of ``config``'s class."""
    for cls, network in _NETWORKS.items():
        if isinstance(config, cls):
            return network(config, shape)
    raise TypeError(f"{type(config).__name__} configures none of fourier, wire, finer, hashgrid")

"""Torch parts networks are built from, and the thesis networks (tanh, PE, SIREN).

Parts: :class:`Linear` (weights (fan_in, fan_out), the layout the numpy reference
and the JAX plugin share), :class:`Sine` (sin(omega0 z)), :class:`PositionalEncoding`
(NeRF's gamma) and :class:`MLP` (linear layers with an activation after each hidden
one). The factory :func:`thesis_network` builds the thesis networks for the shared
trainer; they start from the backend-neutral weights of
:func:`nlosfw.model.reference_state`, so torch and JAX train the same network.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from nlosfw.model import (
    Architecture,
    FieldShape,
    NeuralFieldConfig,
    reference_state,
    thesis_architecture,
)


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
        """The backend-neutral initial weights (see :func:`nlosfw.model.init_parameters`)."""
        return reference_state(self.arch, n_networks, seed)


def thesis_network(config: NeuralFieldConfig, shape: FieldShape) -> ThesisNetwork:
    """The factory of tanh, pe and siren: the network of ``config``'s class, for ``shape``."""
    return ThesisNetwork(thesis_architecture(config, shape))

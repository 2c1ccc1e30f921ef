"""A Fourier-feature MLP (Tancik et al. 2020) in plain torch: any nn.Module will do."""

import math

import torch
from torch import nn

from nlosfw.model.neural import FieldShape
from nlosfw_example_network.hooks import FourierConfig


class FourierFeatureMLP(nn.Module):
    """[cos 2 pi B v, sin 2 pi B v] with B ~ N(0, sigma^2) fixed, then a ReLU MLP.

    v: normalised (x, y[, f]) of shape (N, shape.in_dim); returns (N, 2) = (Re, Im).
    """

    B: torch.Tensor

    def __init__(self, config: FourierConfig, shape: FieldShape) -> None:
        super().__init__()
        # a buffer, not a parameter: saved with the model, never trained
        self.register_buffer("B", config.sigma * torch.randn(shape.in_dim, config.features))
        layers, width = [], 2 * config.features
        for hidden in config.hidden:
            layers += [nn.Linear(width, hidden), nn.ReLU()]
            width = hidden
        self.mlp = nn.Sequential(*layers, nn.Linear(width, shape.out_dim))

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        angle = 2 * math.pi * v @ self.B
        return self.mlp(torch.cat([torch.cos(angle), torch.sin(angle)], dim=-1))

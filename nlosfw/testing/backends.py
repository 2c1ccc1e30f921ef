"""Checks for the backends that run networks (torch, JAX, or a new one).

A backend must run the thesis networks exactly as the independent numpy reference
of :mod:`nlosfw.model.neural.mlp` does: from the same initial weights
(:func:`~nlosfw.model.neural.mlp.init_parameters`), through the same input
encoding (:func:`~nlosfw.model.neural.mlp.network_inputs`) and forward pass
(:func:`~nlosfw.model.neural.mlp.forward_numpy`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nlosfw.model.neural.backend import NetworkBuild
from nlosfw.model.neural.config import FieldShape
from nlosfw.model.neural.mlp import (
    FAMILY_CONFIGS,
    forward_numpy,
    init_parameters,
    network_inputs,
    thesis_architecture,
)
from nlosfw.model.neural.steps import field_inputs
from nlosfw.model.neural.trainer import NeuralFieldModel

#: (family, mode) pairs every backend must evaluate like the numpy reference.
BACKEND_CASES = [(family, mode) for family in ("tanh", "pe", "siren")
                for mode in ("multi", "single")]


def assert_backend_matches_numpy(model_class: type[NeuralFieldModel], mode: str,
                                 rtol: float = 2e-5, atol: float = 2e-5) -> None:
    """A thesis network's field-model class (e.g. ``SirenTorch``) evaluates like
    :func:`forward_numpy` on the weights of :func:`init_parameters`.

    Small networks (16, 12 hidden units; PE with 3 octaves) built by the class's backend
    and factory; 11 random points in (-1, 1) at 3 random frequencies (multi mode); in
    single mode 5 networks, and also a subset of them selected by index.
    """
    family = model_class.family
    options: dict[str, Any] = {"mode": mode, "hidden": (16, 12), "seed": 4, "device": "cpu"}
    if family == "pe":
        options["octaves"] = 3
    config = FAMILY_CONFIGS[family](**options)
    shape = FieldShape(config.mode, (8, 8), 5)
    arch = thesis_architecture(config, shape)
    n_net = 5 if mode == "single" else 0
    net = model_class.backend_class(NetworkBuild(model_class.network_factory, config, shape,
                                                 n_net))
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (11, 2))
    f = rng.uniform(-1, 1, 3) if mode == "multi" else None
    expected = forward_numpy(arch, init_parameters(arch, n_net, seed=4),
                             network_inputs(arch, xy, f))
    x = field_inputs(xy, f)
    np.testing.assert_allclose(net.forward(x), expected, rtol=rtol, atol=atol)
    if mode == "single":
        np.testing.assert_allclose(net.forward(x, np.array([3, 1])), expected[[3, 1]],
                                   rtol=rtol, atol=atol)

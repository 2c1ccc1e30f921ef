"""Checks for backend engines of the neural field models (torch, JAX, or a new backend).

A backend implements :class:`nlosfw.model.trainer.Engine`; these helpers compare it
with the plain numpy forward pass of :mod:`nlosfw.model.networks`, so every backend
computes the same network from the same weights.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from nlosfw.model.networks import (
    FAMILY_CONFIGS,
    forward_numpy,
    init_parameters,
    resolve_architecture,
)

#: (family, mode) pairs every engine must evaluate like the numpy reference.
ENGINE_CASES = [(family, mode) for family in ("tanh", "pe", "siren")
                for mode in ("multi", "single")]


def assert_engine_matches_numpy(make_engine: Callable[..., Any], family: str, mode: str,
                                rtol: float = 2e-5, atol: float = 2e-5) -> None:
    """``make_engine(arch, params, n_networks)`` evaluates like :func:`forward_numpy`.

    Small networks (16, 12 hidden units; PE with 3 octaves), 33 random inputs in
    (-1, 1); in single mode also a subset of the networks selected by index.
    """
    options = {"mode": mode, "hidden": (16, 12)}
    if family == "pe":
        options["octaves"] = 3
    config = FAMILY_CONFIGS[family](**options)
    arch = resolve_architecture(family, config, (8, 8), 5)
    n_net = 5 if mode == "single" else 0
    params = init_parameters(arch, n_net, seed=4)
    engine = make_engine(arch, params, n_net)
    x = np.random.default_rng(0).uniform(-1, 1, (33, arch.in_dim)).astype(np.float32)
    expected = forward_numpy(arch, params, x)
    np.testing.assert_allclose(engine.forward(x), expected, rtol=rtol, atol=atol)
    if mode == "single":
        np.testing.assert_allclose(engine.forward(x, np.array([3, 1])), expected[[3, 1]],
                                   rtol=rtol, atol=atol)

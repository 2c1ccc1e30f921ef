"""Registration of the JAX networks and models (the ``jax`` entry point of ``nlosfw``).

Nothing here imports jax: factories are named by import path.
"""

from __future__ import annotations

from nlosfw.plugins import (
    NetworkRegistrar,
    Registrar,
    hookimpl,
    register_field_networks,
    register_neural_volume,
    register_rsd_residual,
    register_thesis_networks,
)


@hookimpl
def register_networks(register: NetworkRegistrar) -> None:
    register_thesis_networks(register, backend="jax", factory="nlosfw_jax.networks:thesis_network")
    register_field_networks(register, backend="jax", factory="nlosfw_jax.networks:field_network")


@hookimpl
def register_field_models(register: Registrar) -> None:
    register_rsd_residual(register, backend="jax", factory="nlosfw_jax.models:RSDResidualJax")
    register_neural_volume(register, backend="jax",
                           factory="nlosfw_jax.neural_volume:NeuralVolumeJax")

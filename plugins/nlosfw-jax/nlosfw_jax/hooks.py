"""Registration of the JAX networks (the ``jax`` entry point of ``nlosfw``).

Nothing here imports jax: the factory is named by import path.
"""

from __future__ import annotations

from nlosfw.plugins import (
    NetworkRegistrar,
    hookimpl,
    register_field_networks,
    register_thesis_networks,
)


@hookimpl
def register_networks(register: NetworkRegistrar) -> None:
    register_thesis_networks(register, engine="jax", factory="nlosfw_jax.networks:thesis_network")
    register_field_networks(register, engine="jax", factory="nlosfw_jax.networks:field_network")

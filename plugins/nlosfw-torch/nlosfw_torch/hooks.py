"""Registration of the PyTorch networks (the ``torch`` entry point of ``nlosfw``).

Nothing here imports torch: the factory is named by import path.
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
    register_thesis_networks(register, engine="torch",
                             factory="nlosfw_torch.networks:thesis_network")
    register_field_networks(register, engine="torch", factory="nlosfw_torch.networks:field_network")

"""Registration of the PyTorch networks, models and array backend (the ``torch`` entry
point of ``nlosfw``).

Nothing here imports torch: factories are named by import path.
"""

from __future__ import annotations

from nlosfw.plugins import (
    ArrayBackendRegistrar,
    NetworkRegistrar,
    Registrar,
    hookimpl,
    register_ensemble,
    register_field_networks,
    register_neural_volume,
    register_rsd_residual,
    register_thesis_networks,
)


@hookimpl
def register_networks(register: NetworkRegistrar) -> None:
    register_thesis_networks(register, backend="torch",
                             factory="nlosfw_torch.networks:thesis_network")
    register_field_networks(register, backend="torch",
                            factory="nlosfw_torch.networks:field_network")


@hookimpl
def register_field_models(register: Registrar) -> None:
    register_rsd_residual(register, backend="torch", factory="nlosfw_torch.models:RSDResidualTorch")
    register_neural_volume(register, backend="torch",
                           factory="nlosfw_torch.neural_volume:NeuralVolumeTorch")
    register_ensemble(register, backend="torch", factory="nlosfw_torch.ensemble:EnsembleTorch")


@hookimpl
def register_array_backends(register: ArrayBackendRegistrar) -> None:
    register("torch", factory="nlosfw_torch.arrays:TorchArrays",
             counter="nlosfw_torch.arrays:device_count", devices=["cuda"])

"""Registration of the PyTorch networks and models (the ``torch`` entry point of ``nlosfw``).

Nothing here imports torch: factories are named by import path.
"""

from __future__ import annotations

from nlosfw.plugins import (
    Capability,
    NetworkRegistrar,
    Registrar,
    hookimpl,
    register_field_networks,
    register_thesis_networks,
)

#: Small, fast options of rsd_residual for the conformance kit (a tiny physics fit: the
#: kit's plane-wave field is not a hidden scene's, the network fits what it leaves).
RSD_RESIDUAL_TEST_CONFIG = {"iterations": 20, "amplitude": "point", "l1_weight": 0.2,
                            "workers": 1, "depth_range": [0.3, 0.7], "depth_step": 0.1,
                            "fit_frequencies": 0, "power_iterations": 5,
                            "residual_weight": 0.0, "network_steps": 300, "network_lr": 2e-3,
                            "network_batch_size": 0, "network_validation_fraction": 0.0}


@hookimpl
def register_networks(register: NetworkRegistrar) -> None:
    register_thesis_networks(register, engine="torch",
                             factory="nlosfw_torch.networks:thesis_network")
    register_field_networks(register, engine="torch", factory="nlosfw_torch.networks:field_network")


@hookimpl
def register_field_models(register: Registrar) -> None:
    register(
        "rsd_residual_torch",
        "nlosfw_torch.models:RSDResidualTorch",
        config="nlosfw.model.rsd_residual:RSDResidualConfig",
        requires={"torch": "torch==2.13.0"},
        description="rsd_prior's field plus a small penalised residual network (torch)",
        test_config=RSD_RESIDUAL_TEST_CONFIG,
        # not physical_prior: the residual network represents fields no hidden scene makes
        capabilities=[Capability.MULTI_FREQUENCY, Capability.SAVE_LOAD, Capability.NEURAL,
                      Capability.GPU],
    )

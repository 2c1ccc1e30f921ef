"""Registration of the ``embree`` simulator (the ``embree`` entry point of ``nlosfw``).

Nothing here imports embreex: the factory and its config are named by import path.
"""

from __future__ import annotations

from nlosfw.plugins import Capability as C
from nlosfw.plugins import Registrar, hookimpl


@hookimpl
def register_simulators(register: Registrar) -> None:
    register(
        "embree",
        "nlosfw_embree.simulator:EmbreeSimulator",
        config="nlosfw_embree.config:EmbreeConfig",
        requires={"embreex": "embreex"},
        description="Three-bounce transport with Embree occlusion rays (shadows, any mesh)",
        test_config={"samples": 8192},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.DEVICE_LEGS, C.OCCLUSION, C.MESH_FILES],
    )

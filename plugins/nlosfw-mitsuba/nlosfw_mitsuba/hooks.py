"""Registration of the ``mitsuba`` simulator (the ``mitsuba`` entry point of ``nlosfw``).

Nothing here imports mitsuba, drjit or mitransient.
"""

from __future__ import annotations

from nlosfw.plugins import Capability as C
from nlosfw.plugins import Registrar, hookimpl


@hookimpl
def register_simulators(register: Registrar) -> None:
    register(
        "mitsuba",
        "nlosfw_mitsuba.simulator:MitsubaSimulator",
        config="nlosfw_mitsuba.config:MitsubaConfig",
        requires={"mitsuba": "mitsuba", "mitransient": "mitransient"},
        description="Mitsuba 3 + mitransient path tracing (transient_nlos_path, LLVM)",
        test_config={"spp": 1024},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.DEVICE_LEGS, C.OCCLUSION, C.MESH_FILES],
        system_check="nlosfw_mitsuba.llvm:llvm_problem",   # Dr.Jit's LLVM >= 16
    )

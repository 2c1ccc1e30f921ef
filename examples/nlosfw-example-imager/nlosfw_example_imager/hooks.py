"""Registers the imager (the module the entry point names); imports nothing heavy."""

from dataclasses import dataclass

from nlosfw import ImagerConfig, hookimpl, require
from nlosfw.plugins import Registrar


@dataclass(frozen=True)
class BackprojectionConfig(ImagerConfig):
    """Options of the example_backprojection imager."""

    block: int = 256
    """Voxels imaged at once: memory is about block x wall samples x 16 bytes."""

    def __post_init__(self) -> None:
        require(self.block >= 1, "block", f"must be >= 1, got {self.block}")


@hookimpl
def register_imagers(register: Registrar) -> None:
    register(
        "example_backprojection",                               # imager=example_backprojection
        "nlosfw_example_imager.backprojection:BackprojectionImager",   # imported when used
        config=BackprojectionConfig,
        description="Phasor-field backprojection, voxel by voxel (example third-party plugin)",
        test_config={"block": 64},                              # small, fast options for the kit
        # what the conformance kit checks (nlosfw.plugins.CAPABILITIES["imager"]); "rsd":
        # its image is the Rayleigh-Sommerfeld one, compared with the kit's reference
        capabilities=["single_spot", "confocal", "plane_voxels", "point_voxels", "rsd",
                      "progress"],
    )

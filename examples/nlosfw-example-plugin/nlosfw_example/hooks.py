"""Registration of the example plugin (the module named by the entry point)."""

from typing import Any

from nlosfw import hookimpl


@hookimpl
def register_field_models(register: Any) -> None:
    register(
        "nearest",
        "nlosfw_example.nearest:NearestFieldModel",
        config="nlosfw_example.nearest:NearestConfig",
        requires={"scipy": "scipy"},
        description="Nearest wall sample, linear in frequency (example third-party plugin)",
        # what the conformance kit checks (nlosfw.plugins.CAPABILITIES["model"])
        capabilities=["multi_frequency", "single_frequency", "save_load"],
    )

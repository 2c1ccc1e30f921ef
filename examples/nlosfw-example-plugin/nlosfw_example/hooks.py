"""Registration of the example plugin (the module named by the entry point)."""

from nlosfw import hookimpl
from nlosfw.plugins import Registrar


@hookimpl
def register_field_models(register: Registrar) -> None:
    register(
        "nearest",
        "nlosfw_example.nearest:NearestFieldModel",
        config="nlosfw_example.nearest:NearestConfig",
        requires={"scipy": "scipy"},
        description="Nearest wall sample, linear in frequency (example third-party plugin)",
        # its capabilities are declared on NearestFieldModel (``capabilities``)
    )

"""Registers the network (the module the entry point names); imports no torch."""

from dataclasses import dataclass

from nlosfw import hookimpl
from nlosfw.model import NeuralFieldConfig
from nlosfw.plugins import NetworkRegistrar


@dataclass(frozen=True)
class FourierConfig(NeuralFieldConfig):
    """The shared trainer's options (steps, lr, mode, ...) plus the network's own."""

    features: int = 128
    """Rows of B: the MLP sees 2 x features Fourier features."""
    sigma: float = 10.0
    """Standard deviation of B's entries: the bandwidth (inputs lie in (-1, 1))."""
    hidden: tuple[int, ...] = (64, 64)


@hookimpl
def register_networks(register: NetworkRegistrar) -> None:
    register("example_fourier", backend="torch",
             factory="nlosfw_example_network.network:FourierFeatureMLP",
             config=FourierConfig,
             description="Fourier-feature MLP (Tancik et al. 2020), an example plugin",
             test_config={"steps": 300, "batch_size": 0, "validation_fraction": 0.0,
                          "hidden": [32, 32], "features": 32, "sigma": 0.5, "lr": 1e-2})

"""Options of the ``embree`` simulator (a light module: no embreex import)."""

from __future__ import annotations

from dataclasses import dataclass

from nlosfw.common import Choice, require, require_threads
from nlosfw.simulate import SimulatorConfig


class Sampler(Choice):
    """How surface points are drawn."""

    sobol = "sobol"
    independent = "independent"


@dataclass(frozen=True)
class EmbreeConfig(SimulatorConfig):
    """Options of :class:`~nlosfw_embree.simulator.EmbreeSimulator`."""

    samples: int = 131_072
    """Points sampled on the hidden surfaces (area-uniform, shared by every sensor). The
    relative L2 error of H falls about as samples^-0.72 with ``sobol`` (thesis_two_planes,
    64 x 64 x 2048 bins: 2.8% at 65536, 1.6% at 131072); point scatterers are exact."""
    sampler: Sampler = Sampler.sobol
    """``sobol``: scrambled Sobol points (randomised quasi-Monte Carlo, unbiased);
    ``independent``: plain Monte Carlo."""
    threads: int = 0
    """Worker threads (0: every core this process may use). The result does not depend on it."""
    batch: int = 4096
    """Surface samples per vectorised batch (memory grows as batch x sensors along y)."""
    ray_offset: float = 1e-4
    """[m] Distance rays start off a surface, to avoid hitting their own triangle."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.samples >= 1, "samples", f"must be >= 1, got {self.samples}")
        require_threads(self.threads, "threads", 0, "all cores")
        require(self.batch >= 16, "batch", f"must be >= 16 samples, got {self.batch}")
        require(0 < self.ray_offset < 0.01, "ray_offset",
                f"must be in (0, 0.01) metres, got {self.ray_offset}")

"""Options of the ``mitsuba`` simulator (a light module: no mitsuba import)."""

from __future__ import annotations

from dataclasses import dataclass

from nlosfw.common import Choice, require, require_threads
from nlosfw.simulate import SimulatorConfig


class Variant(Choice):
    """The Mitsuba variants mitransient can use (LLVM JIT backends)."""

    llvm_ad_mono = "llvm_ad_mono"
    llvm_ad_rgb = "llvm_ad_rgb"


class Sampler(Choice):
    """Mitsuba sampler plugins."""

    independent = "independent"
    stratified = "stratified"
    multijitter = "multijitter"
    orthogonal = "orthogonal"
    ldsampler = "ldsampler"


@dataclass(frozen=True)
class MitsubaConfig(SimulatorConfig):
    """Options of :class:`~nlosfw_mitsuba.simulator.MitsubaSimulator`."""

    spp: int = 4096
    """Samples (paths) per sensor."""
    variant: Variant = Variant.llvm_ad_mono
    """Mitsuba variant (the LLVM backends; mitransient needs a JIT variant). Grey albedos
    make every rgb channel equal; the capture holds their mean."""
    bounces: int = 3
    """Keep only paths with this many reflections: 3 = relay wall, hidden surface, relay
    wall (the third bounce, as embree and analytic render it); -1 keeps every order up to
    ``max_bounces``."""
    max_bounces: int = 3
    """Longest path traced, in reflections (>= ``bounces`` when that is set)."""
    hidden_geometry_sampling: bool = True
    """mitransient's hidden-geometry sampling: from each wall point, aim at an area-uniform
    point of a hidden surface facing it. Fast, but where a sight line from the wall crosses
    two such surfaces (shadowing) the first one is counted twice (the simulator logs a
    warning when that happens); false: BSDF sampling, unbiased and very slow."""
    sampler: Sampler = Sampler.independent
    """Mitsuba sampler plugin."""
    threads: int = 0
    """Dr.Jit worker threads (0: Dr.Jit's default, every core)."""
    spp_per_pass: int = 0
    """Samples per sensor rendered in one pass (0: as many as keep a pass under 2^26 paths,
    mitransient's own limit); passes use different seeds and are averaged."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.spp >= 1, "spp", f"must be >= 1, got {self.spp}")
        require(self.bounces == -1 or self.bounces >= 3, "bounces",
                f"must be -1 (every order) or >= 3 (3 = third bounce), got {self.bounces}")
        require(self.max_bounces >= 3, "max_bounces", f"must be >= 3, got {self.max_bounces}")
        require(self.bounces == -1 or self.max_bounces >= self.bounces, "max_bounces",
                f"must be >= bounces ({self.bounces}), got {self.max_bounces}")
        require_threads(self.threads, "threads", 0, "all cores")
        require(self.spp_per_pass >= 0, "spp_per_pass",
                f"must be >= 0 (0: automatic), got {self.spp_per_pass}")

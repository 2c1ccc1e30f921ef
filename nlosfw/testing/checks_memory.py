"""The conformance check of a field model's memory estimate
(:meth:`nlosfw.model.FieldModel.estimate_memory`), which a run's plan sums with the
engine's own arrays before anything is allocated (:mod:`nlosfw.pipeline.budget`)."""

from __future__ import annotations

import math
import sys
import tracemalloc

from nlosfw.common.memory import MemoryEstimate, PlanShape
from nlosfw.plugins.registry import PluginSpec

#: Bytes an estimate may allocate while it is computed (it is arithmetic on the options).
MAX_TRACED = 16 * 2**20

#: Run sizes the estimate is asked for: a capture file known from its header alone, then a
#: scene's geometry on a 16 x 16 and a 64 x 64 wall (every fourth point trained on).
SHAPES = (
    PlanShape(bins=512, sensors=256, frequencies=21, training_frequencies=19),
    PlanShape(bins=512, sensors=256, grid=(16, 16), spacing=1 / 16, confocal=True,
              frequencies=21, f_min=1.0, f_max=4.0, training_frequencies=19,
              training=(4, 4), step=4, depth_range=(0.3, 0.9), deepest=1.5),
    PlanShape(bins=2048, sensors=4096, grid=(64, 64), spacing=1 / 64, confocal=True,
              frequencies=151, f_min=4.0, f_max=16.0, training_frequencies=135,
              training=(16, 16), step=4, depth_range=(0.3, 0.9), deepest=1.5),
)


def _check(spec: PluginSpec, estimate: object, shape: PlanShape) -> float:
    who = spec.qualified_name
    assert isinstance(estimate, MemoryEstimate), (
        f"{who}: estimate_memory must return a MemoryEstimate, got {type(estimate).__name__}")
    for part in estimate.parts:
        assert part.what and "\n" not in part.what and "\n" not in part.why, (
            f"{who}: a memory part needs a one-line what and why, got {part!r}")
        assert math.isfinite(part.nbytes) and part.nbytes >= 0, (
            f"{who}: memory part {part.what!r} holds {part.nbytes} bytes for {shape}")
    return estimate.total


def check_memory_estimate(spec: PluginSpec) -> None:
    """The model's class estimates the memory of a fit with its test options for each of
    :data:`SHAPES`: a :class:`~nlosfw.common.memory.MemoryEstimate` of finite,
    non-negative parts with one-line descriptions, the same when asked twice, not smaller
    for the larger wall, and computed from the options and sizes alone: no backend the
    plugin requires is imported by it, and it allocates less than :data:`MAX_TRACED`."""
    cls = spec.load()
    config = spec.make_config(spec.test_config)
    backends = {module.split(".")[0] for module, _ in spec.requires}
    before = {name for name in backends if name in sys.modules}
    tracemalloc.start()
    try:
        totals = [_check(spec, cls.estimate_memory(config, shape), shape) for shape in SHAPES]
        again = _check(spec, cls.estimate_memory(config, SHAPES[-1]), SHAPES[-1])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    imported = sorted(name for name in backends - before if name in sys.modules)
    assert not imported, (f"{spec.qualified_name}: estimate_memory imported {imported}; it "
                          "must be computed from the options alone")
    assert peak < MAX_TRACED, (f"{spec.qualified_name}: estimate_memory allocated "
                               f"{peak / 2**20:.1f} MB; it must allocate nothing large")
    assert again == totals[-1], f"{spec.qualified_name}: estimate_memory is not deterministic"
    assert totals[2] >= totals[1], (
        f"{spec.qualified_name}: estimate_memory gives {totals[2]:.3g} bytes for a 64 x 64 "
        f"wall, less than the {totals[1]:.3g} for a 16 x 16 one")


MEMORY_CHECKS = (check_memory_estimate,)

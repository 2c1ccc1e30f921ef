"""The neural volume's memory estimate sizes the lattice the fit builds: on the wall the
training points lie on, at that wall's own spacing (a random pattern's points lie on the
whole wall's grid, a regular pattern's on every ``step``-th point). The shapes are made as
the run's plan makes them (:class:`~nlosfw.pipeline.plan_capture.TrainingSplit`)."""

from __future__ import annotations

import re

import pytest

from nlosfw.common.memory import PlanShape
from nlosfw.evaluation.splits import SpatialPattern
from nlosfw.model.hybrid.volume_memory import operator_bytes
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.pipeline.plan_capture import TrainingSplit
from nlosfw.pipeline.settings import SplitSettings

#: A 64 x 64 confocal wall 2 cm apart (the shared captures' size), its band to 40 cycles/m.
WALL = PlanShape(bins=512, sensors=64 * 64, grid=(64, 64), spacing=0.02, confocal=True,
                 frequencies=151, f_min=10.0, f_max=40.0, deepest=1.0)


def _planned(step: int, pattern: SpatialPattern) -> PlanShape:
    """The wall's sizes with what the models train on, as the plan gives them."""
    shape = TrainingSplit.of(SplitSettings(spatial_step=step, pattern=pattern)).sized(WALL)
    assert shape.training_frequencies == 135            # 151 less every 10th held out
    return shape


def _voxels(shape: PlanShape) -> tuple[int, int]:
    found = operator_bytes(RSDPriorConfig(), shape)
    assert found is not None
    match = re.search(r"lattice of (\d+) x (\d+) voxels", found[1])
    assert match, found[1]
    return int(match.group(1)), int(match.group(2))


@pytest.mark.parametrize("step", [2, 4, 8])
def test_a_random_pattern_is_sized_on_the_whole_wall_at_its_own_spacing(step):
    """Random points of the 64 x 64 wall: the operator of the wall itself (as with every
    point kept, whose points the fit's lattice is built on), not of a wall ``step`` times
    wider (which counted 96, 340 and 1359 GB here instead of 32)."""
    random = _planned(step, SpatialPattern.random)
    every = _planned(1, SpatialPattern.grid)
    assert random.training == every.training == (64, 64)
    assert operator_bytes(RSDPriorConfig(), random) == operator_bytes(RSDPriorConfig(), every)
    assert _voxels(random) == _voxels(every) == (257, 257)


def test_a_regular_pattern_is_sized_on_every_step_th_point():
    """A grid of every 4th point: 16 x 16 points 8 cm apart."""
    grid = _planned(4, SpatialPattern.grid)
    assert (grid.training, grid.step) == ((16, 16), 4)
    assert _voxels(grid) == (208, 208)


def test_average_steps_adds_the_albedos_it_holds():
    """``average_steps`` holds that many albedos of the lattice's voxels (float32) more; 1
    (the default) adds nothing."""
    import math

    from nlosfw.model.hybrid.volume_memory import volume_memory, volume_planes
    from nlosfw.model.neural.config import NeuralFieldConfig

    shape = _planned(4, SpatialPattern.grid)
    network = NeuralFieldConfig(hidden=[64, 64])
    plain = volume_memory(RSDPriorConfig(), network, "torch", 1.0, shape)
    averaged = volume_memory(RSDPriorConfig(), network, "torch", 1.0, shape, averaged=10)
    added = [p for p in averaged.parts if p not in plain.parts]
    planes = volume_planes(RSDPriorConfig(), shape)
    assert planes is not None
    assert [p.what for p in added] == ["the averaged albedos"]
    assert added[0].nbytes == 10 * planes * math.prod(_voxels(shape)) * 4   # the lattice's
    assert math.prod(_voxels(shape)) > 4 * math.prod(shape.training or (0, 0))
    assert averaged.total - plain.total == added[0].nbytes

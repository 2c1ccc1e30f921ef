"""The sizes a run's plan gives its models' memory estimates of what they train on
(:meth:`~nlosfw.pipeline.plan_capture.TrainingSplit.sized`): the training grid and its
``step``, the training frequencies."""

from __future__ import annotations

import math

import pytest

from nlosfw.common.memory import PlanShape
from nlosfw.evaluation.splits import SpatialPattern
from nlosfw.pipeline.plan_capture import TrainingSplit
from nlosfw.pipeline.settings import SplitSettings

#: A 65 x 63 wall (not a multiple of the steps) of 2 cm, 151 frequencies.
WALL = PlanShape(bins=512, sensors=65 * 63, grid=(65, 63), spacing=0.02, frequencies=151,
                 f_min=10.0, f_max=40.0)


def _sized(shape: PlanShape, split: SplitSettings) -> PlanShape:
    return TrainingSplit.of(split).sized(shape)


@pytest.mark.parametrize("step", [1, 2, 4, 8])
def test_a_grid_pattern_trains_on_every_step_th_wall_point(step):
    """Every ``step``-th point from the first: ceil(n / step) of each side, ``step`` wall
    spacings apart."""
    shape = _sized(WALL, SplitSettings(spatial_step=step))
    assert shape.training == (math.ceil(65 / step), math.ceil(63 / step))
    assert shape.step == step
    assert shape.training_frequencies == 135


@pytest.mark.parametrize("step", [2, 4, 8])
@pytest.mark.parametrize("fraction", [None, 0.5])
def test_a_random_pattern_trains_on_the_whole_wall_grid_one_spacing_apart(step, fraction):
    """A random pattern's points are scattered over the whole wall grid: that grid is its
    training grid (all 65 x 63 points, whichever fraction of them is kept), and the grid's
    own step is 1 wall spacing, not the split's ``spatial_step``."""
    shape = _sized(WALL, SplitSettings(spatial_step=step, pattern=SpatialPattern.random,
                                       spatial_fraction=fraction))
    assert shape.training == (65, 63)
    assert math.prod(shape.training) == shape.sensors
    assert shape.step == 1
    assert shape.training_frequencies == 135


def test_a_shape_without_a_wall_grid_has_no_training_grid():
    """A capture file known from its header alone: no grid yet, so no training grid; the
    training frequencies and step are known."""
    header = PlanShape(bins=512, sensors=4096, lasers=1, frequencies=151)
    grid = _sized(header, SplitSettings(spatial_step=4))
    random = _sized(header, SplitSettings(spatial_step=4, pattern=SpatialPattern.random))
    assert (grid.training, grid.step, grid.training_frequencies) == (None, 4, 135)
    assert (random.training, random.step, random.training_frequencies) == (None, 1, 135)

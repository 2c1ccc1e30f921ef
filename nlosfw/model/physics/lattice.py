"""Where ``rsd_prior`` puts its voxels: the depth planes (given, or found by a quick coarse
fit) and the lateral lattice, and which frequencies its fit uses.

Automatic depth planes: a quick fit of the same problem (``depth_iterations``) on a coarse
lattice (the training spacing laterally, planes a quarter of the shortest wavelength of the
lower half of the band apart, from the wall to half the capture's time span, within the
run's depth range if the field carries it) finds the depths where a plane's largest
contribution ||A e_v|| a_v reaches ``depth_threshold`` of the largest; the fine planes are
those within ``depth_margin`` (plus half a coarse step) of them. Separate objects thus cost
separate clusters of planes, not the whole depth range between them.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from nlosfw.common.errors import FitError
from nlosfw.image.depths import field_depth_range
from nlosfw.image.rsd_kernel import path_multiplier
from nlosfw.model.rsd_config import RSDPriorConfig
from nlosfw.model.rsd_sampling import (
    WallSamples,
    deepest_path,
    enough_frequencies,
    fit_frequency_indices,
    voxel_lattice,
)
from nlosfw.model.scene_operator import OperatorOptions, SceneOperator, VoxelLattice
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

#: ``solve(operator, data, iterations)``: the albedo fitted to ``data`` (rsd_prior's FISTA).
Solve = Callable[[SceneOperator, np.ndarray, int], np.ndarray]


def plan_lattice(config: RSDPriorConfig, values: np.ndarray, samples: WallSamples,
                 field: PhasorField, options: OperatorOptions, solve: Solve
                 ) -> tuple[VoxelLattice, np.ndarray]:
    """The voxel lattice a fit of ``field`` uses (planes over ``depth_range`` or from
    :func:`depth_planes`, ``depth_step`` apart; ``lateral_step``) and the indices of the
    frequencies it fits; ``values`` as for :func:`depth_planes`."""
    shortest = 1.0 / float(field.frequencies.max())
    if config.depth_range:
        near, far = (float(v) for v in config.depth_range)
        step = depth_step(config, field)
        depths = np.arange(near, far + step / 2, step)
    else:
        depths = depth_planes(config, values, samples, field, options, solve)
    lateral = config.lateral_step or shortest / (2 * path_multiplier(field.geometry))
    return (voxel_lattice(samples.layout, lateral, depths),
            fitted_frequencies(config.fit_frequencies, field, depths))


def fitted_frequencies(count: int, field: PhasorField, depths: np.ndarray) -> np.ndarray:
    """The indices of the frequencies a fit on voxel planes at ``depths`` uses: at least
    ``count`` (0: all) evenly spread, and enough that the planes' span does not alias."""
    span = float(depths.max() - depths.min())
    return fit_frequency_indices(field.frequencies, enough_frequencies(
        field.frequencies, count, span))


def depth_step(config: RSDPriorConfig, field: PhasorField) -> float:
    """The distance between voxel planes: ``depth_step``, or a fifth of the field's shortest
    wavelength."""
    return config.depth_step or 1.0 / (5.0 * float(field.frequencies.max()))


def depth_planes(config: RSDPriorConfig, values: np.ndarray, samples: WallSamples,
                 field: PhasorField, options: OperatorOptions, solve: Solve) -> np.ndarray:
    """Planes :func:`depth_step` apart within ``depth_margin`` of the planes where a quick fit on a
    coarse lattice finds the scene (see the module docstring); ``values``: the field
    without device legs on the wall grid of ``samples`` (canonical order, zero where not
    sampled), divided by its RMS; ``options``: the operator's."""
    step = depth_step(config, field)
    deepest = deepest_path(field)
    f = field.frequencies
    lower = np.flatnonzero(f <= f.min() + (f.max() - f.min()) / 2)
    chosen = lower[fit_frequency_indices(f[lower], enough_frequencies(
        f[lower], config.fit_frequencies, deepest))]
    freqs = f[chosen]
    coarse = 1.0 / (4.0 * float(freqs.max()))
    lo, hi = field_depth_range(field) or (coarse, deepest)   # the run's range, if any
    depths = np.arange(max(coarse, lo), max(min(deepest, hi), lo) + coarse / 2, coarse)
    wall = samples.layout
    lattice = voxel_lattice(wall, max(wall.spacing), depths)
    op = SceneOperator(lattice, wall, field.geometry, freqs, options, samples.mask)
    albedo = solve(op, values[chosen], config.depth_iterations)
    contribution = albedo * op.column_norms()
    profile = contribution.reshape(depths.size, -1).max(axis=1)
    if not profile.max() > 0:
        raise FitError("rsd_prior: the coarse fit found no scene; give model.depth_range")
    found = depths[profile >= config.depth_threshold * profile.max()]
    reach = config.depth_margin + coarse / 2
    grid = np.arange(max(step, found.min() - reach), found.max() + reach + step / 2, step)
    near = np.abs(grid[:, None] - found[None, :]).min(axis=1) <= reach
    log.info("rsd_prior: the coarse fit's %d planes (%.3f-%.3f m) find the scene on %d in "
             "%.3f-%.3f m", depths.size, depths[0], depths[-1], found.size, *found[[0, -1]])
    return grid[near]

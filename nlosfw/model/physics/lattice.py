"""Where the physics-constrained fit puts its voxels: the depth planes (given, or found by a
quick coarse fit) and the lateral lattice (:func:`plan_lattice`, which also picks the
frequencies the fit uses, :mod:`nlosfw.model.physics.frequencies`).

Automatic depth planes: a quick fit of the same problem (``depth.iterations``) on a coarse
lattice (the training spacing laterally, planes a quarter of the shortest wavelength of the
lower half of the band apart, from the wall to half the capture's time span, within the
run's depth range if the field carries it) finds the depths where a plane's largest
contribution ||A e_v|| a_v reaches ``depth.threshold`` of the largest; the fine planes are
those within ``depth.margin`` (plus half a coarse step) of them. Separate objects thus cost
separate clusters of planes, not the whole depth range between them.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np

from nlosfw.common.config import number
from nlosfw.common.errors import ConfigError, FitError
from nlosfw.image.plane_convolution import GridLayout
from nlosfw.image.rsd_kernel import path_multiplier
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.model.physics.frequencies import (
    enough_frequencies,
    fit_frequency_indices,
    fitted_frequencies,
)
from nlosfw.model.physics.operator import OperatorOptions, SceneOperator, VoxelLattice
from nlosfw.model.physics.wall import WallSamples
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)

#: ``solve(operator, data, iterations)``: the albedo fitted to ``data`` (rsd_prior's FISTA).
Solve = Callable[[SceneOperator, np.ndarray, int], np.ndarray]


def plan_lattice(config: RSDPriorConfig, values: np.ndarray, samples: WallSamples,
                 field: PhasorField, options: OperatorOptions, solve: Solve
                 ) -> tuple[VoxelLattice, np.ndarray]:
    """The voxel lattice a fit of ``field`` uses (planes over ``depth.range`` or from
    :func:`depth_planes`, ``depth.step`` apart; ``lateral_step``) and the indices of the
    frequencies it fits; ``values`` as for :func:`depth_planes`."""
    shortest = 1.0 / float(field.frequencies.max())
    if config.depth.range:
        near, far = (float(v) for v in config.depth.range)
        step = depth_step(config, field)
        depths = np.arange(near, far + step / 2, step)
    else:
        depths = depth_planes(config, values, samples, field, options, solve)
    lateral = config.lateral_step or shortest / (2 * path_multiplier(field.geometry))
    return (voxel_lattice(samples.layout, lateral, depths),
            fitted_frequencies(config.fit_frequencies, field, depths))


def depth_step(config: RSDPriorConfig, field: PhasorField) -> float:
    """The distance between voxel planes: ``depth.step``, or a fifth of the field's shortest
    wavelength."""
    return config.depth.step or 1.0 / (5.0 * float(field.frequencies.max()))


def depth_planes(config: RSDPriorConfig, values: np.ndarray, samples: WallSamples,
                 field: PhasorField, options: OperatorOptions, solve: Solve) -> np.ndarray:
    """Planes :func:`depth_step` apart within ``depth.margin`` of the planes where a quick fit on a
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
    lo, hi = field.depth_range or (coarse, deepest)   # the run's range, if any
    depths = np.arange(max(coarse, lo), max(min(deepest, hi), lo) + coarse / 2, coarse)
    wall = samples.layout
    lattice = voxel_lattice(wall, max(wall.spacing), depths)
    op = SceneOperator(lattice, wall, field.geometry, freqs, options, samples.mask)
    albedo = solve(op, values[chosen], config.depth.iterations)
    contribution = albedo * op.column_norms()
    profile = contribution.reshape(depths.size, -1).max(axis=1)
    if not profile.max() > 0:
        raise FitError("rsd_prior: the coarse fit found no scene; give model.depth.range")
    found = depths[profile >= config.depth.threshold * profile.max()]
    reach = config.depth.margin + coarse / 2
    grid = np.arange(max(step, found.min() - reach), found.max() + reach + step / 2, step)
    near = np.abs(grid[:, None] - found[None, :]).min(axis=1) <= reach
    log.info("rsd_prior: the coarse fit's %d planes (%.3f-%.3f m) find the scene on %d in "
             "%.3f-%.3f m", depths.size, depths[0], depths[-1], found.size, *found[[0, -1]])
    return grid[near]


def voxel_lattice(wall: GridLayout, lateral_step: float, depths: np.ndarray) -> VoxelLattice:
    """Voxel planes at ``depths`` whose spacing divides the training spacing (at most
    ``lateral_step``) and covering the training grid plus half a training spacing."""
    origin, step, shape = [], [], []
    for axis in (0, 1):
        spacing, n = wall.spacing[axis], wall.shape[axis]
        k = max(1, math.ceil(spacing / lateral_step - 1e-6))
        pad = k // 2
        step.append(spacing / k)
        origin.append(wall.origin[axis] - pad * spacing / k)
        shape.append(k * (n - 1) + 1 + 2 * pad)
    return VoxelLattice(np.asarray(depths, dtype=float), (origin[0], origin[1]),
                        (step[0], step[1]), (shape[0], shape[1]))


def deepest_path(field: PhasorField) -> float:
    """Half the longest path the field can hold: the capture's time span (from the
    transform's metadata) or the unambiguous range 1/df of the frequency spacing."""
    meta = field.metadata
    try:
        t_start, n_bins, delta_t = (number(meta[k]) for k in ("t_start", "n_bins", "delta_t"))
        end = t_start + int(n_bins) * delta_t
        if end > 0:
            return end / 2
    except (KeyError, TypeError, ValueError):
        pass
    f = np.sort(np.unique(field.frequencies))
    if f.size < 2:
        raise ConfigError("model.depth.range", "give [near, far] (m): one frequency and no "
                          "capture time span in the field's metadata cannot place the scene")
    return 1.0 / (2.0 * float(np.min(np.diff(f))))

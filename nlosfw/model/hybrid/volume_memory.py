"""What the neural hidden volume holds while it trains, known before its fit: the operator's
stacked constants (:func:`~nlosfw.model.hybrid.stack.stack_size`) on ``rsd_prior``'s
lattice, and its network's training.

The lattice's depth planes are known only after the quick coarse fit that finds the scene
(:func:`nlosfw.model.physics.lattice.depth_planes`), unless ``prior.depth.range`` gives them;
the estimate bounds them from above: every plane ``depth.step`` apart over the range the
coarse fit searches (the run's depth range, else the wall to half the capture's time span;
its last plane may lie half a coarse step beyond), widened by ``depth.margin`` and half a
coarse step on each side, as the fine planes may be.
The lateral lattice and the frequencies fitted are those the fit chooses
(:func:`~nlosfw.model.physics.lattice.voxel_lattice`,
:func:`~nlosfw.model.physics.frequencies.enough_frequencies`). Without the field's band
(a capture file before it is read) there is no operator term yet.

The network evaluates every voxel in pieces of ``CPU_CHUNK`` on the CPU (its activations
are not kept): a piece's activations count, not the volume's.
"""

from __future__ import annotations

import math

import numpy as np

from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.image.fft import Precision
from nlosfw.image.plane_convolution import GridLayout, GridOrder, PlaneConvolution, lattice_axis
from nlosfw.model.hybrid.stack import stack_size
from nlosfw.model.neural.config import FieldMode, FieldShape, NeuralFieldConfig
from nlosfw.model.neural.memory import network_memory
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.model.physics.frequencies import enough_frequencies, fit_frequency_indices
from nlosfw.model.physics.lattice import voxel_lattice
from nlosfw.model.physics.operator import VoxelLattice

#: Voxels the network evaluates at once on the CPU (the backends' ``CPU_CHUNK``).
CPU_CHUNK = 4096


def volume_planes(prior: RSDPriorConfig, shape: PlanShape) -> int | None:
    """The most depth planes the lattice can have (see the module's documentation); None
    without the field's band."""
    if shape.f_max is None or shape.f_min is None or shape.deepest is None:
        return None
    step = prior.depth.step or 1.0 / (5.0 * shape.f_max)
    if prior.depth.range:
        near, far = prior.depth.range
        return int(np.arange(near, far + step / 2, step).size)
    frequencies = np.linspace(shape.f_min, shape.f_max, max(shape.training_frequencies, 1))
    lower = frequencies[frequencies <= shape.f_min + (shape.f_max - shape.f_min) / 2]
    deepest = shape.deepest
    chosen = lower[fit_frequency_indices(lower, enough_frequencies(
        lower, prior.fit_frequencies, deepest))]
    coarse = 1.0 / (4.0 * float(chosen.max()))
    lo, hi = shape.depth_range or (coarse, deepest)
    near, far = max(coarse, lo), max(min(deepest, hi), lo) + coarse / 2   # the last coarse plane
    reach = prior.depth.margin + coarse / 2
    first = max(step, near - reach)
    return max(1, math.ceil((far + reach - first) / step) + 1)


def _lattice(prior: RSDPriorConfig, shape: PlanShape) -> tuple[GridLayout, VoxelLattice] | None:
    """The training wall's grid and one plane of the voxel lattice on it; None when the
    shape does not know the band, the grid or its spacing."""
    if shape.f_max is None or shape.training is None or shape.spacing is None:
        return None
    multiplier = 2 if shape.confocal else 1
    spacing = shape.spacing * shape.step
    wall = GridLayout(GridOrder(False, False, False), (0.0, 0.0), (spacing, spacing),
                      shape.training)
    lateral = prior.lateral_step or 1.0 / (shape.f_max * 2 * multiplier)
    return wall, voxel_lattice(wall, lateral, np.zeros(1))


def operator_bytes(prior: RSDPriorConfig, shape: PlanShape) -> tuple[float, str] | None:
    """(bytes, why) of the operator's stacked constants on the lattice of ``shape``'s
    training grid; None when the shape does not know the band, the grid or its spacing."""
    planes = volume_planes(prior, shape)
    found = _lattice(prior, shape)
    if planes is None or found is None or shape.f_max is None:
        return None
    wall, lattice = found
    axes = [lattice_axis(lattice.shape[i], lattice.step[i], wall.shape[i], wall.spacing[i],
                         wall.origin[i] - lattice.origin[i]) for i in (0, 1)]
    if axes[0] is None or axes[1] is None:
        return None
    padded = PlaneConvolution(axes[0], axes[1]).shape
    frequencies = np.linspace(shape.f_min or shape.f_max, shape.f_max,
                              max(shape.training_frequencies, 1))
    span = (planes - 1) * (prior.depth.step or 1.0 / (5.0 * shape.f_max))
    fitted = enough_frequencies(frequencies, prior.fit_frequencies, span) or frequencies.size
    fitted = min(fitted, frequencies.size)
    itemsize = 8 if prior.precision == Precision.single else 16
    nbytes = stack_size(planes, fitted, padded, lattice.shape, shape.confocal, itemsize)
    why = (f"at most {planes} planes x {fitted} frequencies on a {padded[0]} x {padded[1]} "
           f"padded lattice of {lattice.shape[0]} x {lattice.shape[1]} voxels")
    return float(nbytes), why


def volume_memory(prior: RSDPriorConfig, network: NeuralFieldConfig, backend: str,
                  stacks: float, shape: PlanShape, averaged: int = 1) -> MemoryEstimate:
    """The operator's constants (``stacks`` copies of them, as the backend holds them), the
    network's training on the voxels (a piece of :data:`CPU_CHUNK` at a time) and, with
    ``averaged`` > 1 (``average_steps``), the last steps' albedos the kept one averages."""
    parts: list[MemoryPart] = []
    operator = operator_bytes(prior, shape)
    planes = volume_planes(prior, shape) or 1
    grid = shape.training or shape.square_grid
    if operator is not None:
        nbytes, why = operator
        parts.append(MemoryPart("the neural volume's operator",
                                why + (f", {stacks:g} copies" if stacks != 1 else ""),
                                nbytes * stacks))
    voxels = float(planes) * math.prod(grid)
    if averaged > 1:
        found = _lattice(prior, shape)
        albedo = planes * math.prod(found[1].shape if found else grid)
        parts.append(MemoryPart("the averaged albedos", f"the last {averaged} steps' albedos "
                                f"of {albedo} voxels (average_steps)", averaged * albedo * 4.0))
    trained = network_memory(network, backend, FieldShape(FieldMode.multi, grid, planes),
                             min(voxels, CPU_CHUNK))
    return MemoryEstimate(tuple(parts)) + trained

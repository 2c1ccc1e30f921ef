"""The physics-constrained fit ``rsd_prior``: the wall field of a non-negative hidden albedo.

A hidden scene (an albedo on voxel planes parallel to the wall) is propagated to the wall
by the :class:`SceneOperator` and fitted to the sparse wall samples by a non-negative,
sparse least-squares solver (:mod:`~nlosfw.model.physics.solver`), on a lattice planned
from the data (:func:`plan_lattice`); terms of real systems (a background, the temporal
response, a glossy lobe) and Poisson likelihoods are fitted jointly
(:class:`RSDPriorFieldModel`). The hybrids (:mod:`nlosfw.model.hybrid`) build on it."""

from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.model.physics.background import Background, WallBackground
    from nlosfw.model.physics.config import (
        CountsOptions,
        DepthOptions,
        LobeOptions,
        PriorOptions,
        ResponseOptions,
        RSDPriorConfig,
    )
    from nlosfw.model.physics.counts import CountsStop
    from nlosfw.model.physics.frequencies import fitted_frequencies
    from nlosfw.model.physics.lattice import plan_lattice, voxel_lattice
    from nlosfw.model.physics.likelihood import Likelihood
    from nlosfw.model.physics.operator import (
        Amplitude,
        OperatorOptions,
        SceneOperator,
        VoxelLattice,
        direct_fields,
    )
    from nlosfw.model.physics.prior import RSDPriorFieldModel
    from nlosfw.model.physics.response import SystemResponse, TemporalResponse
    from nlosfw.model.physics.wall import (
        WallSamples,
        training_grid,
        training_values,
        validation_split,
        wall_samples,
    )

__all__ = [
    "Amplitude",
    "Background",
    "CountsOptions",
    "CountsStop",
    "DepthOptions",
    "direct_fields",
    "fitted_frequencies",
    "Likelihood",
    "LobeOptions",
    "OperatorOptions",
    "plan_lattice",
    "PriorOptions",
    "ResponseOptions",
    "RSDPriorConfig",
    "RSDPriorFieldModel",
    "SceneOperator",
    "SystemResponse",
    "TemporalResponse",
    "training_grid",
    "training_values",
    "validation_split",
    "VoxelLattice",
    "voxel_lattice",
    "wall_samples",
    "WallBackground",
    "WallSamples",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

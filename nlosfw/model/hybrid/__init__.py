"""The hybrids of a neural field and the physics-constrained fit, and the API their backend
plugins build on.

* ``rsd_residual_<backend>`` (:class:`RSDResidualFieldModel`): ``rsd_prior``'s field plus a
  small penalised residual network;
* ``neural_volume_<backend>`` (:class:`NeuralVolumeFieldModel`): a network's non-negative
  albedo on ``rsd_prior``'s lattice, propagated to the wall by the scene operator, which
  each backend writes from the numpy constants of :func:`plane_stack`;
* ``ensemble_<backend>`` (:class:`EnsembleFieldModel`): ``rsd_prior`` at several TV weights
  and the neural volume weighed by their error at held-out kept wall points, plus the
  residual's network on their blend.

Each holds ``rsd_prior``'s options as one group, ``prior``
(:class:`~nlosfw.model.physics.PriorOptions`)."""

from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.model.hybrid.ensemble import EnsembleFieldModel
    from nlosfw.model.hybrid.ensemble_config import EnsembleConfig
    from nlosfw.model.hybrid.folding import FoldedSpectra, fold_spectra
    from nlosfw.model.hybrid.residual import RSDResidualConfig, RSDResidualFieldModel
    from nlosfw.model.hybrid.stack import PlaneStack, aligned_empty, plane_stack, stack_bytes
    from nlosfw.model.hybrid.stacking import HeldOutPoints, held_out_points, simplex_weights
    from nlosfw.model.hybrid.training import BestStep, albedo_total_variation, history_entry
    from nlosfw.model.hybrid.volume import (
        NeuralVolumeFieldModel,
        TrainedVolume,
        VolumeProblem,
        volume_coordinates,
    )
    from nlosfw.model.hybrid.volume_config import NeuralVolumeConfig, VolumePriorOptions

__all__ = [
    "albedo_total_variation",
    "aligned_empty",
    "BestStep",
    "EnsembleConfig",
    "EnsembleFieldModel",
    "fold_spectra",
    "FoldedSpectra",
    "held_out_points",
    "HeldOutPoints",
    "history_entry",
    "NeuralVolumeConfig",
    "NeuralVolumeFieldModel",
    "plane_stack",
    "PlaneStack",
    "RSDResidualConfig",
    "RSDResidualFieldModel",
    "simplex_weights",
    "stack_bytes",
    "TrainedVolume",
    "volume_coordinates",
    "VolumePriorOptions",
    "VolumeProblem",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

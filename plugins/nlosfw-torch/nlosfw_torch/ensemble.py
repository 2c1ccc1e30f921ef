"""``ensemble_torch``: ``rsd_prior``, the torch residual and the torch neural volume weighed
by their error at held-out kept wall points
(:class:`nlosfw.model.hybrid.EnsembleFieldModel`)."""

from __future__ import annotations

from nlosfw.model.hybrid import EnsembleFieldModel, NeuralVolumeFieldModel, RSDResidualFieldModel
from nlosfw_torch.models import RSDResidualTorch
from nlosfw_torch.neural_volume import NeuralVolumeTorch


class EnsembleTorch(EnsembleFieldModel):
    """The stacked ensemble with torch networks; on a GPU when torch sees one."""

    backend = "torch"

    @classmethod
    def residual_class(cls) -> type[RSDResidualFieldModel]:
        """``rsd_residual_torch``."""
        return RSDResidualTorch

    @classmethod
    def volume_class(cls) -> type[NeuralVolumeFieldModel]:
        """``neural_volume_torch``."""
        return NeuralVolumeTorch


__all__ = ["EnsembleTorch"]

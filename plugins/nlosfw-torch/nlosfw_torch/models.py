"""The thesis networks on the torch backend as field-model classes, for use from Python,
and the physics field with a torch residual network.

They are the classes the registry holds as ``tanh_torch``, ``pe_torch``,
``siren_torch`` and ``rsd_residual_torch``: ``SirenTorch({"steps": 3000}).fit(field)``.
"""

from __future__ import annotations

from nlosfw.common import moved_names
from nlosfw.model.hybrid import RSDResidualFieldModel
from nlosfw.model.neural import NeuralFieldModel
from nlosfw.plugins import registered_network, thesis_network_model
from nlosfw_torch.backend import TorchBackend

_FACTORY = "nlosfw_torch.networks:thesis_network"

TanhTorch = thesis_network_model("tanh", "torch", _FACTORY)
PETorch = thesis_network_model("pe", "torch", _FACTORY)
SirenTorch = thesis_network_model("siren", "torch", _FACTORY)


class RSDResidualTorch(RSDResidualFieldModel):
    """rsd_prior's field plus a penalised residual network on the torch backend
    (:class:`nlosfw.model.hybrid.RSDResidualFieldModel`); on a GPU when torch sees one."""

    backend = "torch"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The registered torch network ``name``'s field-model class."""
        return registered_network(name, "torch")


__all__ = ["PETorch", "RSDResidualTorch", "SirenTorch", "TanhTorch", "TorchBackend"]
#: ``TorchEngine``, the backend's name here before "engine" meant the run engine only.
__getattr__ = moved_names(__name__, {"TorchEngine": "nlosfw_torch.backend:TorchBackend"})

"""The thesis networks on the JAX backend as field-model classes, for use from Python,
and the physics field with a JAX residual network.

They are the classes the registry holds as ``tanh_jax``, ``pe_jax``, ``siren_jax`` and
``rsd_residual_jax``.
"""

from __future__ import annotations

from nlosfw.common import moved_names
from nlosfw.model.hybrid import RSDResidualFieldModel
from nlosfw.model.neural import NeuralFieldModel
from nlosfw.plugins import registered_network, thesis_network_model
from nlosfw_jax.backend import JaxBackend

_FACTORY = "nlosfw_jax.networks:thesis_network"

TanhJax = thesis_network_model("tanh", "jax", _FACTORY)
PEJax = thesis_network_model("pe", "jax", _FACTORY)
SirenJax = thesis_network_model("siren", "jax", _FACTORY)


class RSDResidualJax(RSDResidualFieldModel):
    """rsd_prior's field plus a penalised residual network on the JAX backend
    (:class:`nlosfw.model.hybrid.RSDResidualFieldModel`); on a GPU when JAX sees one."""

    backend = "jax"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The registered JAX network ``name``'s field-model class."""
        return registered_network(name, "jax")


__all__ = ["JaxBackend", "PEJax", "RSDResidualJax", "SirenJax", "TanhJax"]
#: ``JaxEngine``, the backend's name here before "engine" meant the run engine only.
__getattr__ = moved_names(__name__, {"JaxEngine": "nlosfw_jax.backend:JaxBackend"})

"""The thesis networks on the JAX engine as field-model classes, for use from Python.

They are the classes the registry holds as ``tanh_jax``, ``pe_jax`` and ``siren_jax``.
"""

from __future__ import annotations

from nlosfw.plugins import thesis_network_model
from nlosfw_jax.engine import JaxEngine

_FACTORY = "nlosfw_jax.networks:thesis_network"

TanhJax = thesis_network_model("tanh", "jax", _FACTORY)
PEJax = thesis_network_model("pe", "jax", _FACTORY)
SirenJax = thesis_network_model("siren", "jax", _FACTORY)

__all__ = ["JaxEngine", "PEJax", "SirenJax", "TanhJax"]

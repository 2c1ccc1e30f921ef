"""The thesis networks on the torch engine as field-model classes, for use from Python.

They are the classes the registry holds as ``tanh_torch``, ``pe_torch`` and
``siren_torch``: ``SirenTorch({"steps": 3000}).fit(field)``.
"""

from __future__ import annotations

from nlosfw.plugins import thesis_network_model
from nlosfw_torch.engine import TorchEngine

_FACTORY = "nlosfw_torch.networks:thesis_network"

TanhTorch = thesis_network_model("tanh", "torch", _FACTORY)
PETorch = thesis_network_model("pe", "torch", _FACTORY)
SirenTorch = thesis_network_model("siren", "torch", _FACTORY)

__all__ = ["PETorch", "SirenTorch", "TanhTorch", "TorchEngine"]

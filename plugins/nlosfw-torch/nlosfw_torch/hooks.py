"""Registration of the PyTorch field models (the ``torch`` entry point of ``nlosfw``).

Nothing here imports torch: factories and configs are named by import path.
"""

from __future__ import annotations

from typing import Any

from nlosfw.plugins import Capability as C
from nlosfw.plugins import hookimpl

_REQUIRES = {"torch": "torch==2.13.0"}
#: Small, fast settings for the conformance kit (tiny fields: full batch, small networks,
#: since more parameters than half the data values over-fit, thesis sec. 4.2).
_TEST_CONFIG = {"steps": 300, "batch_size": 0, "eval_every": 50, "validation_fraction": 0.0,
                "hidden": [32, 32]}
_TEST_LR = {"tanh": 5e-3, "pe": 5e-3, "siren": 2e-3}

_MODELS = {
    "tanh": ("TanhTorch", "TanhFieldConfig", "MLP with tanh activations (thesis F_w,M), PyTorch"),
    "pe": ("PETorch", "PEFieldConfig",
           "MLP on NeRF's positional encoding (thesis F_w,P and F_P), PyTorch"),
    "siren": ("SirenTorch", "SirenFieldConfig",
              "SIREN: sine activations, Sitzmann init (thesis F_S), PyTorch"),
}


@hookimpl
def register_field_models(register: Any) -> None:
    for family, (cls, config, description) in _MODELS.items():
        register(
            f"{family}_torch",
            f"nlosfw_torch.models:{cls}",
            config=f"nlosfw.model:{config}",
            requires=_REQUIRES,
            description=description,
            test_config={**_TEST_CONFIG, "lr": _TEST_LR[family]},
            capabilities=[C.MULTI_FREQUENCY, C.SAVE_LOAD, C.NEURAL, C.GPU],
        )

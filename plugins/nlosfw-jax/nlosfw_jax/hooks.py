"""Registration of the JAX field models (the ``jax`` entry point of ``nlosfw``).

Nothing here imports jax: factories and configs are named by import path.
"""

from __future__ import annotations

from typing import Any

from nlosfw.plugins import Capability as C
from nlosfw.plugins import hookimpl

_REQUIRES = {"jax": "jax", "optax": "optax"}
#: Small, fast settings for the conformance kit (tiny fields: full batch, small networks,
#: since more parameters than half the data values over-fit, thesis sec. 4.2).
_TEST_CONFIG = {"steps": 300, "batch_size": 0, "eval_every": 50, "validation_fraction": 0.0,
                "hidden": [32, 32]}
_TEST_LR = {"tanh": 5e-3, "pe": 5e-3, "siren": 2e-3}

_MODELS = {
    "tanh": ("TanhJax", "TanhFieldConfig", "MLP with tanh activations (thesis F_w,M), JAX"),
    "pe": ("PEJax", "PEFieldConfig",
           "MLP on NeRF's positional encoding (thesis F_w,P and F_P), JAX"),
    "siren": ("SirenJax", "SirenFieldConfig",
              "SIREN: sine activations, Sitzmann init (thesis F_S), JAX"),
}


@hookimpl
def register_field_models(register: Any) -> None:
    for family, (cls, config, description) in _MODELS.items():
        register(
            f"{family}_jax",
            f"nlosfw_jax.models:{cls}",
            config=f"nlosfw.model:{config}",
            requires=_REQUIRES,
            description=description,
            test_config={**_TEST_CONFIG, "lr": _TEST_LR[family]},
            capabilities=[C.MULTI_FREQUENCY, C.SAVE_LOAD, C.NEURAL, C.GPU],
        )

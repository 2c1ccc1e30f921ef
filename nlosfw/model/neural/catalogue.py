"""The networks the torch and JAX plugins register for the shared trainer, by name: the
thesis's coordinate MLPs (tanh, pe, siren; :mod:`nlosfw.model.neural.mlp`) with the thesis's
presets, and fourier, wire, finer and hashgrid (:mod:`nlosfw.model.neural.encodings`,
:mod:`nlosfw.model.neural.activations`) with their initial weights; and the conformance
kit's short settings for each."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import DataError
from nlosfw.model.neural.activations import (
    FinerFieldConfig,
    WireFieldConfig,
    finer_state,
    wire_state,
)
from nlosfw.model.neural.config import FieldShape, NeuralFieldConfig, Preset
from nlosfw.model.neural.encodings import (
    FourierFieldConfig,
    HashGridFieldConfig,
    fourier_state,
    hashgrid_state,
)
from nlosfw.model.neural.mlp import (
    FAMILY_CONFIGS,
    PEFieldConfig,
    SirenFieldConfig,
    TanhFieldConfig,
)

# --------------------------------------------------------------------------- presets
_THESIS_TRAINING = {"lr": 1e-3, "lr_schedule": "constant", "batch_size": 0, "steps": 100_000,
                    "validation_fraction": 0.0}

#: The thesis's four networks (ch. 4, Table 4.1) with its training recipe (lr 1e-3, full
#: batch, 100,000 steps: about 9 h on 2 CPU cores; override ``steps`` for a quicker fit).
PRESETS: dict[str, Preset] = {
    "thesis_tanh_single": Preset(
        "tanh", {"mode": "single", "hidden": (20, 20, 20), **_THESIS_TRAINING}, 942,
        "MLP + tanh, one frequency: 2 -> 20 -> 20 -> 20 -> 2"),
    "thesis_pe_single": Preset(
        "pe", {"mode": "single", "hidden": (16, 16, 16), "octaves": 5, "include_input": False,
               "activation": "relu", **_THESIS_TRAINING}, 914,
        "MLP + positional encoding (L = 5, no raw input), one frequency: 20 -> 16 x3 -> 2"),
    "thesis_pe_multi": Preset(
        "pe", {"mode": "multi", "hidden": (32, 32, 32, 32), "octaves": 5,
               "include_input": False, "frequency_input": "raw", "activation": "relu",
               **_THESIS_TRAINING}, 3938,
        "MLP + positional encoding of (x, y) and raw f: 21 -> 32 x4 -> 2"),
    "thesis_siren": Preset(
        "siren", {"mode": "multi", "hidden": (32, 32, 32, 32), "omega0_first": 30.0,
                  "omega0_hidden": 30.0, **_THESIS_TRAINING}, 3362,
        "SIREN, multi frequency: 3 -> 32 x4 (sine) -> 2 (linear)"),
}


def presets_of(family: str) -> dict[str, Preset]:
    """The presets of one network family (``tanh``, ``pe`` or ``siren``)."""
    return {name: p for name, p in PRESETS.items() if p.family == family}


def preset_config(name: str, **overrides: Any) -> NeuralFieldConfig:
    """The config of preset ``name`` with some options overridden (e.g. ``steps=2000``)."""
    if name not in PRESETS:
        raise DataError(f"preset: unknown preset {name!r}; valid: {', '.join(sorted(PRESETS))}")
    preset = PRESETS[name]
    return config_from_mapping(FAMILY_CONFIGS[preset.family], {**preset.options, **overrides},
                               "model")


@dataclass(frozen=True)
class ThesisNetwork:
    """How the torch and JAX plugins register one thesis network."""

    config: type[NeuralFieldConfig]
    description: str
    test_lr: float
    """Learning rate of the conformance kit's short fits."""


#: The three thesis networks, by registered name (each backend appends ``_torch``/``_jax``).
THESIS_NETWORKS: dict[str, ThesisNetwork] = {
    "tanh": ThesisNetwork(TanhFieldConfig, "MLP with tanh activations (thesis F_w,M)", 5e-3),
    "pe": ThesisNetwork(PEFieldConfig,
                        "MLP on NeRF's positional encoding (thesis F_w,P and F_P)", 5e-3),
    "siren": ThesisNetwork(SirenFieldConfig,
                           "SIREN: sine activations, Sitzmann init (thesis F_S)", 2e-3),
}

#: Small, fast settings for the conformance kit (tiny fields: full batch, small networks,
#: since more parameters than half the data values over-fit, thesis sec. 4.2).
THESIS_TEST_CONFIG: dict[str, Any] = {"steps": 300, "batch_size": 0, "eval_every": 50,
                                      "validation_fraction": 0.0, "hidden": [32, 32]}


# ---------------------------------------------------------- fourier, wire, finer, hashgrid
_STATES: dict[type, Callable[..., dict[str, np.ndarray]]] = {
    FourierFieldConfig: fourier_state,
    WireFieldConfig: wire_state,
    FinerFieldConfig: finer_state,
    HashGridFieldConfig: hashgrid_state,
}


def field_network_state(config: NeuralFieldConfig, shape: FieldShape, n_networks: int, seed: int
                  ) -> dict[str, np.ndarray]:
    """The initial arrays (float32, by name) of the network ``config`` configures; with
    ``n_networks`` > 0 each gets a leading axis of that length (single mode)."""
    rng = np.random.default_rng([int(seed), 0x696E72])  # "inr" stream
    lead = (n_networks,) if n_networks > 0 else ()
    for cls, state in _STATES.items():
        if isinstance(config, cls):
            return dict(state(config, shape, rng, lead))
    valid = ", ".join(c.__name__ for c in _STATES)
    raise DataError(f"model: {type(config).__name__} configures none of the networks "
                    f"fourier, wire, finer, hashgrid; valid: {valid}")


@dataclass(frozen=True)
class FieldNetwork:
    """How the torch and JAX plugins register one of these networks."""

    config: type[NeuralFieldConfig]
    description: str
    test_config: Mapping[str, object]
    """Small, fast options for the conformance kit."""


_TEST = {"steps": 300, "batch_size": 0, "eval_every": 50, "validation_fraction": 0.0}

#: The four networks, by registered name (each backend appends ``_torch`` / ``_jax``).
FIELD_NETWORKS: dict[str, FieldNetwork] = {
    "fourier": FieldNetwork(FourierFieldConfig, "Fourier-feature MLP (Tancik et al. 2020)",
                            {**_TEST, "hidden": [32, 32], "features": 32, "sigma": 0.5,
                             "lr": 1e-2}),
    "wire": FieldNetwork(WireFieldConfig, "WIRE: complex Gabor wavelet activations, complex "
                         "output (Saragadam et al. 2023)",
                         {**_TEST, "hidden": [24, 24], "omega0": 5.0, "scale0": 2.0,
                          "lr": 5e-3}),
    "finer": FieldNetwork(FinerFieldConfig, "FINER: variable-periodic sin((|z|+1) z) "
                          "activations (Liu et al. 2024)",
                          {**_TEST, "hidden": [32, 32], "lr": 2e-3}),
    "hashgrid": FieldNetwork(HashGridFieldConfig, "Multiresolution hash-grid encoding and a "
                             "small MLP (Mueller et al. 2022), plain torch/JAX",
                             {**_TEST, "hidden": [32], "levels": 4, "base_resolution": 2,
                              "finest_resolution": 8, "lr": 1e-2}),
}

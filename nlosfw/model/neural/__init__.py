"""Neural fields: a network plus the shared trainer, whatever the backend.

A neural field model is a network plus :class:`NeuralFieldModel` (normalisation, batches,
validation, schedule, files, prediction). A network plugin supplies a factory building a
torch or JAX module for a :class:`FieldShape` and a config deriving from
:class:`NeuralFieldConfig`; the backend plugin's :class:`Backend` runs it. The networks
registered by the torch and JAX plugins are described backend-neutrally here: the
thesis's coordinate MLPs (tanh, pe, siren: :class:`Architecture`, :func:`forward_numpy`,
...) and fourier, wire, finer and hashgrid (:func:`field_network_state`, ...).

The names in ``__all__`` are the API backend and network plugins build on."""

from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.model.neural.activations import FinerFieldConfig, WireFieldConfig, wire_widths
    from nlosfw.model.neural.backend import (
        PREDICT_CHUNK,
        Backend,
        DeviceArray,
        NetworkBuild,
        SmoothnessBatch,
    )
    from nlosfw.model.neural.catalogue import (
        FIELD_NETWORKS,
        PRESETS,
        THESIS_NETWORKS,
        FieldNetwork,
        ThesisNetwork,
        field_network_state,
        preset_config,
    )
    from nlosfw.model.neural.config import (
        FieldMode,
        FieldShape,
        LRSchedule,
        NeuralFieldConfig,
        Preset,
    )
    from nlosfw.model.neural.encodings import (
        HASH_PRIMES,
        FourierFieldConfig,
        HashGridFieldConfig,
        HashGridLayout,
        hash_grid_layout,
    )
    from nlosfw.model.neural.mlp import (
        Architecture,
        PEFieldConfig,
        SirenFieldConfig,
        TanhFieldConfig,
        forward_numpy,
        init_parameters,
        network_inputs,
        reference_state,
        resolve_architecture,
        thesis_architecture,
    )
    from nlosfw.model.neural.normalisation import FieldNormalisation
    from nlosfw.model.neural.trainer import NeuralFieldModel

__all__ = [
    "Architecture",
    "Backend",
    "DeviceArray",
    "field_network_state",
    "FIELD_NETWORKS",
    "FieldMode",
    "FieldNetwork",
    "FieldNormalisation",
    "FieldShape",
    "FinerFieldConfig",
    "forward_numpy",
    "FourierFieldConfig",
    "HASH_PRIMES",
    "hash_grid_layout",
    "HashGridFieldConfig",
    "HashGridLayout",
    "init_parameters",
    "LRSchedule",
    "network_inputs",
    "NetworkBuild",
    "NeuralFieldConfig",
    "NeuralFieldModel",
    "PEFieldConfig",
    "PREDICT_CHUNK",
    "Preset",
    "preset_config",
    "PRESETS",
    "reference_state",
    "resolve_architecture",
    "SirenFieldConfig",
    "SmoothnessBatch",
    "TanhFieldConfig",
    "thesis_architecture",
    "THESIS_NETWORKS",
    "ThesisNetwork",
    "wire_widths",
    "WireFieldConfig",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

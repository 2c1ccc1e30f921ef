"""Stage 3, field models: continuous F(x, y, f) -> P fitted to sparse phasor fields,
and the protocol that scores them.

A neural field model is a network plus the shared trainer (:class:`NeuralFieldModel`):
a network plugin supplies a factory building a torch or JAX module for a
:class:`FieldShape` and a config deriving from :class:`NeuralFieldConfig`; the
backend's :class:`Engine` runs it. The thesis's tanh, PE and SIREN networks are
described backend-neutrally in :mod:`nlosfw.model.thesis_networks`.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.model.engine import PREDICT_CHUNK, Engine, NetworkBuild, SmoothnessBatch
    from nlosfw.model.inr_networks import (
        FIELD_NETWORKS,
        HASH_PRIMES,
        FieldNetwork,
        FinerFieldConfig,
        FourierFieldConfig,
        HashGridFieldConfig,
        HashGridLayout,
        WireFieldConfig,
        field_network_state,
        hash_grid_layout,
        wire_widths,
    )
    from nlosfw.model.interface import FieldModel, FieldModelConfig, FitReport, TrainingStep
    from nlosfw.model.interp import InterpConfig, InterpFieldModel
    from nlosfw.model.model_files import read_model_file, write_model_file
    from nlosfw.model.neural_config import (
        FieldMode,
        FieldShape,
        LRSchedule,
        NeuralFieldConfig,
        Preset,
    )
    from nlosfw.model.normalisation import FieldNormalisation, estimate_delay
    from nlosfw.model.protocol import (
        FieldSplit,
        SpatialPattern,
        SpatialSampling,
        error_metrics,
        field_metrics,
        heldout_frequency_indices,
        hull_mask,
        parameter_data_ratio,
        scattered_field,
        split_field,
    )
    from nlosfw.model.smoothness import FrequencySmoothness, second_difference_matrix
    from nlosfw.model.thesis_networks import (
        FAMILY_CONFIGS,
        PRESETS,
        THESIS_NETWORKS,
        THESIS_TEST_CONFIG,
        Architecture,
        FrequencyInput,
        PEActivation,
        PEFieldConfig,
        SirenFieldConfig,
        TanhFieldConfig,
        ThesisNetwork,
        count_parameters,
        forward_numpy,
        init_parameters,
        network_inputs,
        parameter_names,
        positional_encoding,
        preset_config,
        presets_of,
        reference_state,
        resolve_architecture,
        thesis_architecture,
    )
    from nlosfw.model.trainer import NeuralFieldModel, field_inputs, learning_rate

__all__ = [
    "Architecture",
    "count_parameters",
    "Engine",
    "error_metrics",
    "estimate_delay",
    "FAMILY_CONFIGS",
    "field_inputs",
    "field_metrics",
    "FIELD_NETWORKS",
    "FieldMode",
    "FieldModel",
    "FieldModelConfig",
    "FieldNetwork",
    "FieldNormalisation",
    "FieldShape",
    "FieldSplit",
    "FinerFieldConfig",
    "FitReport",
    "forward_numpy",
    "FourierFieldConfig",
    "FrequencyInput",
    "FrequencySmoothness",
    "hash_grid_layout",
    "HASH_PRIMES",
    "HashGridFieldConfig",
    "HashGridLayout",
    "heldout_frequency_indices",
    "hull_mask",
    "init_parameters",
    "field_network_state",
    "InterpConfig",
    "InterpFieldModel",
    "learning_rate",
    "LRSchedule",
    "network_inputs",
    "NetworkBuild",
    "NeuralFieldConfig",
    "NeuralFieldModel",
    "parameter_data_ratio",
    "parameter_names",
    "PEActivation",
    "PEFieldConfig",
    "positional_encoding",
    "PREDICT_CHUNK",
    "Preset",
    "preset_config",
    "PRESETS",
    "presets_of",
    "read_model_file",
    "reference_state",
    "resolve_architecture",
    "second_difference_matrix",
    "SirenFieldConfig",
    "SmoothnessBatch",
    "scattered_field",
    "SpatialPattern",
    "SpatialSampling",
    "split_field",
    "TanhFieldConfig",
    "thesis_architecture",
    "THESIS_NETWORKS",
    "THESIS_TEST_CONFIG",
    "ThesisNetwork",
    "TrainingStep",
    "wire_widths",
    "WireFieldConfig",
    "write_model_file",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

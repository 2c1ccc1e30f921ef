"""Stage 3, field models: continuous F(x, y, f) -> P fitted to sparse phasor fields,
and the protocol that scores them.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from nlosfw.model.interface import FieldModel, FieldModelConfig, FitReport, TrainingStep
from nlosfw.model.interp import InterpConfig, InterpFieldModel
from nlosfw.model.networks import (
    FAMILY_CONFIGS,
    PRESETS,
    Architecture,
    FieldNormalisation,
    NeuralFieldConfig,
    PEFieldConfig,
    Preset,
    SirenFieldConfig,
    TanhFieldConfig,
    count_parameters,
    estimate_delay,
    forward_numpy,
    init_parameters,
    learning_rate,
    network_inputs,
    positional_encoding,
    preset_config,
    presets_of,
    read_model_file,
    resolve_architecture,
    write_model_file,
)
from nlosfw.model.protocol import (
    FieldSplit,
    error_metrics,
    field_metrics,
    heldout_frequency_indices,
    hull_mask,
    parameter_data_ratio,
    split_field,
)
from nlosfw.model.trainer import PREDICT_CHUNK, Engine, NeuralFieldModel

__all__ = [
    "Architecture",
    "count_parameters",
    "Engine",
    "error_metrics",
    "estimate_delay",
    "FAMILY_CONFIGS",
    "field_metrics",
    "FieldModel",
    "FieldModelConfig",
    "FieldNormalisation",
    "FieldSplit",
    "FitReport",
    "forward_numpy",
    "heldout_frequency_indices",
    "hull_mask",
    "init_parameters",
    "InterpConfig",
    "InterpFieldModel",
    "learning_rate",
    "network_inputs",
    "NeuralFieldConfig",
    "NeuralFieldModel",
    "parameter_data_ratio",
    "PEFieldConfig",
    "positional_encoding",
    "PREDICT_CHUNK",
    "Preset",
    "preset_config",
    "PRESETS",
    "presets_of",
    "read_model_file",
    "resolve_architecture",
    "SirenFieldConfig",
    "split_field",
    "TanhFieldConfig",
    "TrainingStep",
    "write_model_file",
]

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
    from nlosfw.model.engine import Engine, NetworkBuild, SmoothnessBatch
    from nlosfw.model.inr_networks import (
        HASH_PRIMES,
        FinerFieldConfig,
        FourierFieldConfig,
        HashGridFieldConfig,
        HashGridLayout,
        WireFieldConfig,
        field_network_state,
        hash_grid_layout,
        wire_widths,
    )
    from nlosfw.model.interface import (
        FieldModel,
        FieldModelConfig,
        FitReport,
        TrainingStep,
        check_query,
        check_training_field,
    )
    from nlosfw.model.interp import InterpConfig, InterpFieldModel
    from nlosfw.model.model_files import read_model_file, write_model_file
    from nlosfw.model.neural_config import (
        FieldMode,
        FieldShape,
        LRSchedule,
        NeuralFieldConfig,
        Preset,
    )
    from nlosfw.model.neural_volume import (
        NeuralVolumeConfig,
        NeuralVolumeFieldModel,
        TrainedVolume,
        VolumeProblem,
        volume_coordinates,
    )
    from nlosfw.model.normalisation import FieldNormalisation
    from nlosfw.model.protocol import (
        FieldSplit,
        SpatialSampling,
        field_metrics,
        parameter_data_ratio,
        split_field,
    )
    from nlosfw.model.rsd_residual import RSDResidualConfig, RSDResidualFieldModel
    from nlosfw.model.rsd_sampling import WallSamples, training_grid, voxel_lattice, wall_samples
    from nlosfw.model.scene_operator import OperatorOptions, SceneOperator, VoxelLattice
    from nlosfw.model.spectra_folding import FoldedSpectra, fold_spectra
    from nlosfw.model.thesis_networks import (
        Architecture,
        ThesisNetwork,
        forward_numpy,
        init_parameters,
        network_inputs,
        preset_config,
        reference_state,
        resolve_architecture,
        thesis_architecture,
    )
    from nlosfw.model.trainer import NeuralFieldModel
    from nlosfw.model.volume_training import (
        BestStep,
        PlaneStack,
        aligned_empty,
        history_entry,
        plane_stack,
        stack_bytes,
        validation_split,
    )

__all__ = [
    "FieldNormalisation",
    "forward_numpy",
    "network_inputs",
    "resolve_architecture",
    "check_training_field",
    "check_query",
    "Architecture",
    "Engine",
    "field_metrics",
    "FieldMode",
    "FieldModel",
    "FieldModelConfig",
    "FieldShape",
    "FieldSplit",
    "FinerFieldConfig",
    "FitReport",
    "FourierFieldConfig",
    "hash_grid_layout",
    "HASH_PRIMES",
    "HashGridFieldConfig",
    "HashGridLayout",
    "init_parameters",
    "field_network_state",
    "InterpConfig",
    "InterpFieldModel",
    "LRSchedule",
    "NetworkBuild",
    "OperatorOptions",
    "NeuralFieldConfig",
    "NeuralFieldModel",
    "BestStep",
    "history_entry",
    "NeuralVolumeConfig",
    "NeuralVolumeFieldModel",
    "PlaneStack",
    "FoldedSpectra",
    "fold_spectra",
    "aligned_empty",
    "plane_stack",
    "stack_bytes",
    "validation_split",
    "parameter_data_ratio",
    "Preset",
    "preset_config",
    "read_model_file",
    "reference_state",
    "RSDResidualConfig",
    "RSDResidualFieldModel",
    "SceneOperator",
    "SmoothnessBatch",
    "SpatialSampling",
    "split_field",
    "thesis_architecture",
    "ThesisNetwork",
    "training_grid",
    "TrainedVolume",
    "TrainingStep",
    "volume_coordinates",
    "VolumeProblem",
    "VoxelLattice",
    "voxel_lattice",
    "wall_samples",
    "WallSamples",
    "wire_widths",
    "WireFieldConfig",
    "write_model_file",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

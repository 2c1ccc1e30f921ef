"""Stage 3, field models: continuous F(x, y, f) -> P fitted to sparse phasor fields (the
protocol that splits and scores them is :mod:`nlosfw.evaluation`).

The root holds the :class:`FieldModel` interface, the ``interp`` baseline, the model files
and what users import (the models' configs); the model families are subpackages:

* :mod:`nlosfw.model.neural`: neural fields, a network plus the shared trainer
  (:class:`~nlosfw.model.neural.NeuralFieldModel`); its ``__all__`` is the API the torch
  and JAX backend plugins and network plugins build on (the backend's
  :class:`~nlosfw.model.neural.Backend`, the network catalogue);
* :mod:`nlosfw.model.physics`: the physics-constrained fit ``rsd_prior`` (scene operator,
  solver, lattice, its terms and likelihoods);
* :mod:`nlosfw.model.hybrid`: the hybrids ``rsd_residual_<backend>`` and
  ``neural_volume_<backend>``, which build on both.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these and the subpackages' ``__all__``. The names the backends use that this
package exported before (``Engine``, ``NetworkBuild``, ``PlaneStack``, ...), and the
protocol's (``split_field``, ``field_metrics``, ...), still load from here for one minor
version, with a :class:`DeprecationWarning` naming their new place."""


from typing import TYPE_CHECKING

from nlosfw.common.deprecation import moved_names
from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.model.hybrid.residual import RSDResidualConfig
    from nlosfw.model.hybrid.volume_config import NeuralVolumeConfig
    from nlosfw.model.interface import (
        FieldModel,
        FieldModelConfig,
        FitReport,
        ModelNeeds,
        TrainingStep,
        check_query,
        check_training_field,
    )
    from nlosfw.model.interp import InterpConfig, InterpFieldModel
    from nlosfw.model.model_files import read_model_file, write_model_file
    from nlosfw.model.neural.catalogue import preset_config
    from nlosfw.model.neural.config import NeuralFieldConfig
    from nlosfw.model.physics.config import RSDPriorConfig
    from nlosfw.model.physics.prior import RSDPriorFieldModel

__all__ = [
    "check_query",
    "check_training_field",
    "FieldModel",
    "FieldModelConfig",
    "FitReport",
    "ModelNeeds",
    "InterpConfig",
    "InterpFieldModel",
    "NeuralFieldConfig",
    "NeuralVolumeConfig",
    "preset_config",
    "read_model_file",
    "RSDPriorConfig",
    "RSDPriorFieldModel",
    "RSDResidualConfig",
    "TrainingStep",
    "write_model_file",
]

_NEURAL = ("Architecture", "field_network_state", "FieldMode", "FieldNormalisation",
           "FieldShape", "FinerFieldConfig", "forward_numpy", "FourierFieldConfig",
           "HASH_PRIMES", "hash_grid_layout", "HashGridFieldConfig", "HashGridLayout",
           "init_parameters", "LRSchedule", "network_inputs", "NetworkBuild",
           "NeuralFieldModel", "Preset", "reference_state", "resolve_architecture",
           "SmoothnessBatch", "thesis_architecture", "ThesisNetwork", "wire_widths",
           "WireFieldConfig")
_PHYSICS = ("OperatorOptions", "SceneOperator", "training_grid", "validation_split",
            "VoxelLattice", "voxel_lattice", "wall_samples", "WallSamples")
_HYBRID = ("aligned_empty", "BestStep", "fold_spectra", "FoldedSpectra", "history_entry",
           "NeuralVolumeFieldModel", "plane_stack", "PlaneStack", "RSDResidualFieldModel",
           "stack_bytes", "TrainedVolume", "volume_coordinates", "VolumeProblem")
#: The protocol's names this package exported before :mod:`nlosfw.evaluation` held them.
_EVALUATION = ("FieldSplit", "SpatialSampling", "field_metrics", "parameter_data_ratio",
               "split_field")
#: The names this package exported before the families became subpackages (and before the
#: protocol became a package) -> their place.
MOVED = {"Engine": "nlosfw.model.neural:Backend",
         **{n: f"nlosfw.evaluation:{n}" for n in _EVALUATION},
         **{n: f"nlosfw.model.neural:{n}" for n in _NEURAL},
         **{n: f"nlosfw.model.physics:{n}" for n in _PHYSICS},
         **{n: f"nlosfw.model.hybrid:{n}" for n in _HYBRID}}

_lazy_getattr, __dir__ = lazy_exports(__name__, __file__)
__getattr__ = moved_names(__name__, MOVED, _lazy_getattr)

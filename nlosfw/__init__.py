"""nlosfw: non-line-of-sight transient imaging with implicit neural phasor fields.

The package is organised by pipeline stage, each a subpackage whose ``__all__`` is
its public API:

* :mod:`nlosfw.capture`: the transient capture, its geometry and file formats;
* :mod:`nlosfw.simulate`: scenes and the simulators that render them;
* :mod:`nlosfw.transform`: phasor fields and the transforms that make them;
* :mod:`nlosfw.model`: field models fitted to sparse fields, and their protocol;
* :mod:`nlosfw.image`: imagers and reconstructions;
* :mod:`nlosfw.plugins`: plugin discovery and hooks; :mod:`nlosfw.testing`: the kit;
* :mod:`nlosfw.app`: the command line (Hydra), pipeline, cache, figures and reports.

Importing this package loads only numpy, scipy and the core data types; plugins and
their heavy backends (torch, JAX, mitsuba, embreex) load on demand.
"""

from nlosfw.capture import (
    Capture,
    CaptureFormat,
    CaptureFormatConfig,
    CaptureGeometry,
    CaptureKind,
    GridFormat,
    HFormat,
    VolumeFormat,
)
from nlosfw.common import (
    ConfigError,
    DataError,
    FitError,
    NlosfwError,
    PluginError,
    __version__,
    require,
)
from nlosfw.image import Imager, ImagerConfig, Reconstruction
from nlosfw.model import FieldModel, FieldModelConfig, FitReport, TrainingStep
from nlosfw.plugins import Capability, PluginKind, hookimpl
from nlosfw.simulate import Scene, Simulator, SimulatorConfig
from nlosfw.transform import PhasorField, PhasorTransform, PhasorTransformConfig

__all__ = [
    "Capability", "Capture", "CaptureFormat", "CaptureFormatConfig", "CaptureGeometry",
    "CaptureKind", "ConfigError", "DataError",
    "FieldModel", "FieldModelConfig", "FitError", "FitReport", "GridFormat", "HFormat", "Imager",
    "ImagerConfig", "NlosfwError", "PhasorField", "PhasorTransform", "PhasorTransformConfig",
    "PluginError", "PluginKind", "Reconstruction", "Scene", "Simulator", "SimulatorConfig",
    "TrainingStep", "VolumeFormat", "__version__", "hookimpl", "require",
]

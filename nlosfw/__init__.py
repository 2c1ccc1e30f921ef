"""nlosfw: non-line-of-sight transient imaging with implicit neural phasor fields.

Importing this package loads only numpy and the core data types; plugins and
their heavy backends (torch, JAX, mitsuba, embreex) load on demand.
"""

from nlosfw.capture import Capture, CaptureGeometry
from nlosfw.enums import CaptureKind, GridFormat, HFormat, PluginKind, VolumeFormat
from nlosfw.errors import ConfigError, DataError, FitError, NlosfwError, PluginError
from nlosfw.interfaces import (
    FieldModel,
    FieldModelConfig,
    FitReport,
    Imager,
    ImagerConfig,
    PhasorTransform,
    PhasorTransformConfig,
    Simulator,
    SimulatorConfig,
    TrainingStep,
)
from nlosfw.phasor_field import PhasorField
from nlosfw.plugins.hookspecs import hookimpl
from nlosfw.reconstruction import Reconstruction
from nlosfw.scene import Scene

__version__ = "0.1.0"

__all__ = [
    "Capture", "CaptureGeometry", "CaptureKind", "ConfigError", "DataError", "FieldModel",
    "FieldModelConfig", "FitError", "FitReport", "GridFormat", "HFormat", "Imager",
    "ImagerConfig", "NlosfwError", "PhasorField", "PhasorTransform", "PhasorTransformConfig",
    "PluginError", "PluginKind", "Reconstruction", "Scene", "Simulator", "SimulatorConfig",
    "TrainingStep", "VolumeFormat", "hookimpl", "__version__",
]

"""nlosfw: non-line-of-sight transient imaging with implicit neural phasor fields.

The package is organised by pipeline stage, each a subpackage whose ``__all__`` is
its public API:

* :mod:`nlosfw.capture`: the transient capture, its geometry and file formats;
* :mod:`nlosfw.simulate`: scenes and the simulators that render them;
* :mod:`nlosfw.transform`: phasor fields and the transforms that make them;
* :mod:`nlosfw.model`: field models fitted to sparse fields;
* :mod:`nlosfw.image`: imagers and reconstructions;
* :mod:`nlosfw.evaluation`: the protocol: splits, count splitting, field and image scores;
* :mod:`nlosfw.plugins`: plugin discovery and hooks; :mod:`nlosfw.testing`: the kit;
* :mod:`nlosfw.pipeline`: the run engine (plans, stages, cache, run directory, metrics);
* :mod:`nlosfw.compose`: a run's configuration composed with Hydra and checked;
* :mod:`nlosfw.report`: figures and reports; :mod:`nlosfw.cli`: the command line.

For notebooks and scripts, :mod:`nlosfw.api` gives one function per stage and one for a
whole run, all importable from here: :func:`load_capture` (any capture format),
:func:`read_capture` (HDF5), :func:`simulate_scene`,
:func:`transform_capture`, :func:`split_field`, :func:`fit_model`, :func:`predict_field`,
:func:`reconstruct` and :func:`run` (``nlosfw.run(["model=interp"])`` is
``python -m nlosfw model=interp``, returning the results instead of printing them).

Importing this package loads nothing else: each public name here loads its stage (numpy,
scipy, h5py, ...) on first use; plugins and their heavy backends (torch, JAX, mitsuba,
embreex), Hydra, rich and matplotlib load on demand.
"""

from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # the names, for type checkers; at run time they load on first use
    from nlosfw.api import (
        fit_model,
        load_capture,
        predict_field,
        reconstruct,
        run,
        simulate_scene,
        transform_capture,
    )
    from nlosfw.capture import (
        Capture,
        CaptureFormat,
        CaptureFormatConfig,
        CaptureGeometry,
        CaptureKind,
        GridFormat,
        HFormat,
        VolumeFormat,
        read_capture,
        write_capture,
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
    from nlosfw.evaluation import field_metrics, split_field
    from nlosfw.image import Imager, ImagerConfig, Reconstruction, depth_span
    from nlosfw.model import (
        FieldModel,
        FieldModelConfig,
        FitReport,
        TrainingStep,
    )
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
    # the Python API (nlosfw.api): one function per stage, and a whole run
    "depth_span", "field_metrics", "fit_model", "load_capture", "predict_field", "read_capture",
    "reconstruct", "run", "simulate_scene", "split_field", "transform_capture", "write_capture",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

"""Infrastructure every stage shares: errors, typed configs, atomic files, cores.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from nlosfw.common.config import (
    Choice,
    Configurable,
    config_from_mapping,
    config_to_dict,
    require,
    require_finite,
    require_seed,
    require_threads,
)
from nlosfw.common.cores import available_cores
from nlosfw.common.deprecation import moved_names
from nlosfw.common.errors import (
    USER_ERROR_EXIT_STATUS,
    ConfigError,
    DataError,
    FitError,
    NlosfwError,
    PluginError,
    one_line,
)
from nlosfw.common.files import atomic_path, write_text
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.common.progress import ProgressCallback, accepts_progress
from nlosfw.common.text import markdown, override_value
from nlosfw.common.version import __version__

__all__ = [
    "__version__",
    "accepts_progress",
    "atomic_path",
    "available_cores",
    "Choice",
    "config_from_mapping",
    "config_to_dict",
    "ConfigError",
    "Configurable",
    "DataError",
    "FitError",
    "MemoryEstimate",
    "MemoryPart",
    "moved_names",
    "NlosfwError",
    "one_line",
    "markdown",
    "override_value",
    "PlanShape",
    "PluginError",
    "ProgressCallback",
    "require",
    "require_finite",
    "require_seed",
    "require_threads",
    "USER_ERROR_EXIT_STATUS",
    "write_text",
]

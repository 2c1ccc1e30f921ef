"""The plugin system: discovery through the ``nlosfw`` entry-point group, registries, hooks.

Entry points in the ``nlosfw`` group name plugin modules; their hook
implementations register factories by name into one registry per kind. Loading
the registries imports the plugin modules only: factories (and with them
torch, JAX, mitsuba or embreex) are imported when a plugin is instantiated.
Plugins declare what they can do from their kind's :data:`CAPABILITIES` vocabulary.
Networks registered through ``register_networks`` become field models
``<name>_<backend>`` (:mod:`nlosfw.plugins.networks`); array backends registered through
``register_array_backends`` run the FFT-based imagers on a GPU
(:mod:`nlosfw.plugins.array_backends`).
"""

from nlosfw.common.deprecation import moved_names
from nlosfw.plugins.array_backends import (
    ArrayBackendRegistrar,
    ArrayBackendSpec,
    bind_device,
    check_device,
)
from nlosfw.plugins.capabilities import DEFAULTS as DEFAULT_CAPABILITIES
from nlosfw.plugins.capabilities import VOCABULARY as CAPABILITIES
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.hookspecs import hookimpl, hookspec
from nlosfw.plugins.kinds import INTERFACES, RUN_KINDS, PluginKind
from nlosfw.plugins.manager import (
    ENTRY_POINT_GROUP,
    ENV_VAR,
    PluginHost,
    current_host,
    hosting,
    load_plugins,
    registered_network,
    registered_networks,
)
from nlosfw.plugins.networks import (
    BACKENDS,
    NetworkBackend,
    NetworkKwargs,
    NetworkOptions,
    NetworkRegistrar,
    NetworkSpec,
    network_model,
    register_ensemble,
    register_field_networks,
    register_neural_volume,
    register_rsd_residual,
    register_thesis_networks,
    thesis_network_model,
)
from nlosfw.plugins.registry import (
    LazyFactory,
    PluginSpec,
    Registrar,
    RegistrationKwargs,
    Registry,
    import_object,
)

__all__ = [
    "ArrayBackendRegistrar",
    "ArrayBackendSpec",
    "bind_device",
    "check_device",
    "CAPABILITIES",
    "DEFAULT_CAPABILITIES",
    "Capability",
    "BACKENDS",
    "ENTRY_POINT_GROUP",
    "ENV_VAR",
    "INTERFACES",
    "LazyFactory",
    "NetworkBackend",
    "NetworkKwargs",
    "NetworkOptions",
    "NetworkRegistrar",
    "NetworkSpec",
    "PluginHost",
    "PluginKind",
    "PluginSpec",
    "Registrar",
    "RegistrationKwargs",
    "Registry",
    "RUN_KINDS",
    "hookimpl",
    "hookspec",
    "import_object",
    "current_host",
    "hosting",
    "load_plugins",
    "network_model",
    "register_ensemble",
    "register_field_networks",
    "register_neural_volume",
    "register_rsd_residual",
    "register_thesis_networks",
    "registered_network",
    "registered_networks",
    "thesis_network_model",
]

#: Names this package exported before "engine" came to mean the run engine only.
__getattr__ = moved_names(__name__, {"NetworkEngine": "nlosfw.plugins.networks:NetworkBackend",
                                     "ENGINES": "nlosfw.plugins.networks:BACKENDS"})

"""Plugin discovery and registries.

Entry points in the ``nlosfw`` group name plugin modules; their hook
implementations register factories by name into one registry per kind. Loading
the registries imports the plugin modules only: factories (and with them
torch, JAX, mitsuba or embreex) are imported when a plugin is instantiated.
"""

from nlosfw.plugins.hookspecs import hookimpl
from nlosfw.plugins.manager import ENV_VAR, PluginHost, load_plugins
from nlosfw.plugins.registry import PluginSpec, Registry

__all__ = ["ENV_VAR", "PluginHost", "PluginSpec", "Registry", "hookimpl", "load_plugins"]

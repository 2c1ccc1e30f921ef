"""Discover plugin modules through entry points and collect their registrations.

A command builds one :class:`PluginHost` (:func:`load_plugins`) and makes it the host of
what it runs (:func:`hosting`); what needs the registry within (:func:`current_host`: a
model finding its registered network) uses that one instead of building another. Each
build raises the audit event ``nlosfw.plugins.load`` (:func:`sys.audit`)."""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from functools import partial
from importlib.metadata import entry_points
from types import ModuleType
from typing import TYPE_CHECKING

import pluggy

from nlosfw.capture.source import FormatCatalogue
from nlosfw.common.errors import ConfigError
from nlosfw.plugins import hookspecs
from nlosfw.plugins.array_backends import ArrayBackendRegistrar
from nlosfw.plugins.kinds import PluginKind
from nlosfw.plugins.networks import NetworkRegistrar, NetworkSpec
from nlosfw.plugins.registry import PluginSpec, Registrar, Registry

if TYPE_CHECKING:
    from nlosfw.model.neural.trainer import NeuralFieldModel

log = logging.getLogger(__name__)

#: Entry-point group naming plugin modules.
ENTRY_POINT_GROUP = "nlosfw"

#: Environment variable that blocks (``-name``) or allows (``name``) plugins, comma separated.
#: Names match a plugin (``siren_jax``), a kind-qualified plugin (``model:siren_jax``)
#: or an entry point (``jax``). If any name is allowed, only allowed plugins load.
ENV_VAR = "NLOSFW_PLUGINS"

_HOOK_OF_KIND = {
    PluginKind.SIMULATOR: "register_simulators",
    PluginKind.PHASOR_TRANSFORM: "register_phasor_transforms",
    PluginKind.FIELD_MODEL: "register_field_models",
    PluginKind.IMAGER: "register_imagers",
    PluginKind.CAPTURE_FORMAT: "register_capture_formats",
}
_NETWORK_HOOK = "register_networks"
_ARRAYS_HOOK = "register_array_backends"


@dataclass(frozen=True)
class PluginFilter:
    """Which plugins to load, from the ``NLOSFW_PLUGINS`` environment variable."""

    allow: frozenset[str] = frozenset()
    block: frozenset[str] = frozenset()

    @classmethod
    def parse(cls, text: str) -> PluginFilter:
        allow, block = set(), set()
        for token in (t.strip() for t in text.split(",")):
            if not token:
                continue
            if token.startswith("-"):
                block.add(token[1:].strip())
            else:
                allow.add(token.lstrip("+").strip())
        return cls(frozenset(allow), frozenset(block))

    def loads_entry_point(self, entry_point: str) -> bool:
        return entry_point not in self.block

    def accepts(self, spec: PluginSpec) -> bool:
        names = {spec.name, spec.qualified_name, spec.entry_point}
        if names & self.block:
            return False
        return not self.allow or bool(names & self.allow)


@dataclass
class PluginHost:
    """The pluggy manager with every plugin module loaded, and the resulting registry."""

    manager: pluggy.PluginManager
    registry: Registry
    broken: dict[str, str] = field(default_factory=dict)
    """Entry points that failed to load: name -> one-line reason."""

    @property
    def hook(self) -> pluggy.HookRelay:
        """Call lifecycle hooks: ``host.hook.on_run_start(run_dir=..., config=...)``."""
        return self.manager.hook

    def capture_formats(self) -> FormatCatalogue:
        """The registered capture formats (detection asks those whose requirements are
        installed), as the capture stage takes them."""
        specs = self.registry.specs(PluginKind.CAPTURE_FORMAT)
        return FormatCatalogue(
            factories={spec.name: partial(spec.create, {}) for spec in specs},
            installed=frozenset(s.name for s in specs if not s.missing_requirements()))


def load_plugins(env: Mapping[str, str] | None = None,
                 extra: Sequence[tuple[str, str, ModuleType | object]] = ()) -> PluginHost:
    """Load every plugin module of the ``nlosfw`` entry-point group and build the registry.

    ``env`` defaults to ``os.environ`` (for ``NLOSFW_PLUGINS``). ``extra`` adds
    in-process plugin modules as ``(distribution, name, module)`` triples, for
    tests and embedding. No plugin factory is imported here.
    """
    sys.audit("nlosfw.plugins.load")
    env = os.environ if env is None else env
    rules = PluginFilter.parse(env.get(ENV_VAR, ""))
    manager = pluggy.PluginManager(hookspecs.PROJECT)
    manager.add_hookspecs(hookspecs)
    origins: dict[str, tuple[str, str]] = {}
    broken: dict[str, str] = {}
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if not rules.loads_entry_point(ep.name):
            continue
        dist = ep.dist.metadata["Name"] if ep.dist is not None else "unknown"
        try:
            module = ep.load()
        except Exception as err:  # a broken third-party plugin must not break the others
            broken[ep.name] = f"{dist}: {type(err).__name__}: {err}"
            log.warning("nlosfw plugin %r from %s failed to load: %s", ep.name, dist, err)
            continue
        key = f"{dist}:{ep.name}"
        if manager.is_registered(module) or manager.has_plugin(key):
            continue
        manager.register(module, name=key)
        origins[key] = (dist, ep.name)
    for dist, name, module in extra:
        key = f"{dist}:{name}"
        manager.register(module, name=key)
        origins[key] = (dist, name)

    registry = Registry()
    # networks register field models (``<name>_<backend>``), after the kinds' own hooks
    hooks = [*_HOOK_OF_KIND.items(), (PluginKind.FIELD_MODEL, _NETWORK_HOOK)]
    for kind, hook_name in hooks:
        for key, (dist, ep_name) in origins.items():
            others = [p for k, p in manager.list_name_plugin() if k != key]
            caller = manager.subset_hook_caller(hook_name, remove_plugins=others)
            register = Registrar(kind, dist, ep_name, rules.accepts, registry)
            caller(register=NetworkRegistrar(register) if hook_name == _NETWORK_HOOK
                   else register)
    for key, (dist, _) in origins.items():
        others = [p for k, p in manager.list_name_plugin() if k != key]
        caller = manager.subset_hook_caller(_ARRAYS_HOOK, remove_plugins=others)
        caller(register=ArrayBackendRegistrar(dist, registry.array_backends))
    return PluginHost(manager=manager, registry=registry, broken=broken)


_HOST: ContextVar[PluginHost | None] = ContextVar("nlosfw_plugin_host", default=None)


@contextmanager
def hosting(host: PluginHost) -> Iterator[PluginHost]:
    """``host`` is the plugin host of what runs in the block (:func:`current_host`)."""
    token = _HOST.set(host)
    try:
        yield host
    finally:
        _HOST.reset(token)


def current_host() -> PluginHost:
    """The host of the command running (:func:`hosting`), else a new one."""
    host = _HOST.get()
    return load_plugins() if host is None else host


def _network_specs(backend: str) -> dict[str, PluginSpec]:
    return {spec.factory.name: spec for spec in current_host().registry.specs("model")
            if isinstance(spec.factory, NetworkSpec) and spec.factory.backend.value == backend}


def registered_networks(backend: str) -> list[str]:
    """The names of the networks registered through ``register_networks`` for ``backend``
    (``torch``, ``jax``), sorted."""
    return sorted(_network_specs(backend))


def registered_network(name: str, backend: str) -> type[NeuralFieldModel]:
    """The field-model class of the network ``name`` registered through ``register_networks``
    for ``backend`` (``siren`` and ``torch``: ``siren_torch``'s class). A one-line
    ConfigError on ``model.network`` lists the valid names."""
    networks = _network_specs(backend)
    if name not in networks:
        raise ConfigError("model.network", f"{name!r} is not a network registered for "
                          f"{backend}; valid: {', '.join(sorted(networks)) or 'none'}")
    model: type[NeuralFieldModel] = networks[name].load()
    return model


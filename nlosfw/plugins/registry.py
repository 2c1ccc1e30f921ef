"""Plugin specifications and the per-kind registry. A :class:`PluginSpec` names a factory
lazily (``"package.module:Class"``) so that listing plugins never imports a heavy backend;
the factory is imported when :meth:`PluginSpec.create` is first called."""

from __future__ import annotations

import importlib
import importlib.util
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import TYPE_CHECKING, Any, Literal, TypedDict, TypeVar, overload

from nlosfw.capture.formats import CaptureFormat
from nlosfw.common.config import Configurable, config_from_mapping
from nlosfw.common.errors import PluginError
from nlosfw.image.interface import Imager
from nlosfw.model.interface import FieldModel
from nlosfw.plugins.capabilities import Capability, parse_capabilities
from nlosfw.plugins.kinds import INTERFACES, PluginKind
from nlosfw.simulate.interface import Simulator
from nlosfw.transform.interface import PhasorTransform

if TYPE_CHECKING:
    from typing_extensions import Unpack

    from nlosfw.plugins.array_backends import ArrayBackendSpec

T = TypeVar("T")

#: A plugin's options: a mapping of them, a config instance, or None (the defaults).
PluginOptions = Mapping[str, object] | object | None


def module_of(path: str) -> str:
    """The module part of ``"package.module:attr"`` (or ``"package.module.attr"``)."""
    module_name, _, attr = path.partition(":")
    return module_name if attr else path.rpartition(".")[0]


def import_object(path: str) -> Any:
    """Import ``"package.module:attr"`` (or ``"package.module.attr"``)."""
    module_name = module_of(path)
    attr = path[len(module_name) + 1:]
    module = importlib.import_module(module_name)
    obj: Any = module
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


class LazyFactory(ABC):
    """A factory made on first use (e.g. a field model bound to a registered network)."""

    @abstractmethod
    def load(self) -> Any:
        """The factory (imports what it needs)."""

    def import_paths(self) -> tuple[str, ...]:
        """The ``"module:attr"`` paths :meth:`load` imports (checked, without importing them,
        when plugins are listed); default none."""
        return ()


@dataclass(frozen=True)
class PluginSpec:
    """One registered plugin: what it is, where it comes from, how to build it."""

    kind: PluginKind
    name: str
    factory: str | Callable[..., Any] | LazyFactory
    """The implementation class, ``"module:Class"`` imported on first use, or a
    :class:`LazyFactory` that makes it on first use."""
    distribution: str
    """The installed distribution that registered it (``nlosfw``, ``nlosfw-torch``, ...)."""
    entry_point: str = ""
    config: str | type | None = None
    """Config dataclass (or ``"module:Class"``); default the factory's ``config_class``."""
    requires: tuple[tuple[str, str], ...] = ()
    """(importable module, pip requirement) pairs the factory needs."""
    description: str = ""
    test_config: Mapping[str, object] = field(default_factory=dict)
    """Small, fast settings used by the conformance checks."""
    expected_failures: Mapping[str, str] = field(default_factory=dict)
    """Conformance check (``check_x`` or ``check_x[variant]``) -> the known bug that makes
    it fail; it runs as a strict xfail. Not for what the plugin cannot do: declare
    ``capabilities`` instead."""
    declared_capabilities: tuple[str, ...] | None = None
    """What the plugin declared it can do in its ``register()`` call (``None``: nothing
    there; the class's ``capabilities`` then apply, see :attr:`capabilities`)."""
    system_check: str | None = None
    """``"module:function"`` of a light function: '' or what the machine lacks outside
    Python, in one line (:func:`nlosfw.testing.system_problem` calls it)."""

    def __post_init__(self) -> None:
        if self.declared_capabilities is not None:
            found = parse_capabilities(self.kind, self.label, self.declared_capabilities)
            object.__setattr__(self, "declared_capabilities",
                               tuple(sorted(found, key=lambda c: c.value)))
        else:
            parse_capabilities(self.kind, self.label, None)

    @property
    def qualified_name(self) -> str:
        return f"{self.kind.value}:{self.name}"

    @property
    def label(self) -> str:
        """``<distribution>: <kind> plugin '<name>'``, for messages."""
        return f"{self.distribution}: {self.kind.value} plugin '{self.name}'"

    @property
    def capabilities(self) -> frozenset[Capability]:
        """What the plugin can do: as declared in its ``register()`` call, else as its class
        declares (its ``capabilities`` class attribute; the factory is imported to read it),
        else the kind's defaults (:data:`nlosfw.plugins.capabilities.DEFAULTS`)."""
        declared = self.declared_capabilities
        if declared is None:
            declared = self.class_capabilities()
        return parse_capabilities(self.kind, self.label, declared)

    @property
    def capabilities_origin(self) -> Literal["registration", "class", "defaults"]:
        """Where :attr:`capabilities` come from."""
        if self.declared_capabilities is not None:
            return "registration"
        return "class" if self.class_capabilities() is not None else "defaults"

    def class_capabilities(self) -> tuple[str, ...] | None:
        """The ``capabilities`` the plugin's class declares (``None``: none, or the factory
        is not a class, or cannot be imported)."""
        if self.missing_requirements():
            return None
        try:
            factory = self.load()
        except PluginError:
            return None
        declared = getattr(factory, "capabilities", None) if isinstance(factory, type) else None
        if declared is None:
            return None
        return _as_tuple(declared, self.kind, self.label)

    def missing_requirements(self) -> list[tuple[str, str]]:
        """Required modules that cannot be found (checked without importing them)."""
        missing = []
        for module, requirement in self.requires:
            try:
                found = importlib.util.find_spec(module) is not None
            except (ImportError, ValueError):
                found = False
            if not found:
                missing.append((module, requirement))
        return missing

    def install_command(self) -> str:
        """The pip command that installs the missing requirements ('' if none are missing)."""
        missing = self.missing_requirements()
        if not missing:
            return ""
        return "pip install " + " ".join(_quote(req) for _, req in missing)

    def import_paths(self) -> tuple[str, ...]:
        """Every ``"module:attr"`` path the factory and the config are imported from."""
        paths = []
        if isinstance(self.factory, str):
            paths.append(self.factory)
        elif isinstance(self.factory, LazyFactory):
            paths.extend(self.factory.import_paths())
        if isinstance(self.config, str):
            paths.append(self.config)
        return tuple(dict.fromkeys(paths))

    def find_problem(self) -> str:
        """Why the factory's or the config's module cannot be found ('' when all are found).

        Uses :func:`importlib.util.find_spec`, which imports the parent packages of each
        module but not the module itself, so no heavy backend is imported.
        """
        for path in self.import_paths():
            module = module_of(path)
            try:
                found = importlib.util.find_spec(module) is not None
            except ModuleNotFoundError:   # a parent package is missing
                found = False
            except Exception as err:  # a parent package that fails to import, a bad name
                return f"module {module} of {path} cannot be found: {type(err).__name__}: {err}"
            if not found:
                return f"module {module} of {path} not found"
        return ""

    def import_problem(self) -> str:
        """Why the factory or the config cannot be imported ('' when both import).

        Imports them (and with them any heavy backend): for ``plugins --check`` and
        ``plugins NAME``, and before a run uses the plugin.
        """
        try:
            self.load()
            self.config_class()
        except PluginError as err:
            return str(err)
        return ""

    def load(self) -> Any:
        """The factory, imported on first use; a one-line error says what to install, or
        why the factory cannot be imported."""
        if not isinstance(self.factory, (str, LazyFactory)):
            return self.factory
        command = self.install_command()
        if command:
            modules = ", ".join(m for m, _ in self.missing_requirements())
            raise PluginError(f"{self.kind.value} plugin '{self.name}' needs {modules}, which is "
                              f"not installed; run: {command}")
        try:
            if isinstance(self.factory, LazyFactory):
                return self.factory.load()
            return import_object(self.factory)
        except PluginError:
            raise
        except Exception as err:  # any failure importing a plugin's code is the plugin's bug
            raise PluginError(f"{self.kind.value} plugin '{self.name}' (from {self.distribution}) "
                              f"cannot be imported: {_reason(err)}") from err

    def config_class(self) -> type:
        """The config dataclass (imports ``config`` if it is a path, else the factory)."""
        if self.config is None:
            return self.load().config_class
        if isinstance(self.config, str):
            try:
                return import_object(self.config)
            except Exception as err:
                raise PluginError(f"{self.kind.value} plugin '{self.name}': config class "
                                  f"{self.config} cannot be imported: {_reason(err)}") from err
        return self.config

    def make_config(self, options: Mapping[str, object] | None = None) -> Any:
        """A validated config instance; errors name ``<kind>.<option>``."""
        return config_from_mapping(self.config_class(), options, self.kind.value)

    def create(self, options: Mapping[str, Any] | Any = None) -> Any:
        """Instantiate the plugin with ``options`` (a mapping or a config instance)."""
        config = options if isinstance(options, self.config_class()) else self.make_config(options)
        return self.load()(config)


class Registry:
    """Plugins of every kind by name. Duplicate names within a kind are errors."""

    def __init__(self, specs: Iterable[PluginSpec] = ()) -> None:
        self._specs: dict[tuple[PluginKind, str], PluginSpec] = {}
        #: The array backends registered (:mod:`nlosfw.plugins.array_backends`).
        self.array_backends: dict[str, ArrayBackendSpec] = {}
        for spec in specs:
            self.add(spec)

    def add(self, spec: PluginSpec) -> None:
        key = (spec.kind, spec.name)
        if key in self._specs:
            other = self._specs[key]
            raise PluginError(f"duplicate {spec.kind.value} plugin '{spec.name}': registered by "
                              f"{other.distribution} and by {spec.distribution}; uninstall one "
                              "or block one with NLOSFW_PLUGINS=-<name>")
        self._specs[key] = spec

    def get(self, kind: PluginKind | str, name: str) -> PluginSpec:
        kind = PluginKind(kind)
        try:
            return self._specs[(kind, name)]
        except KeyError:
            valid = ", ".join(self.names(kind)) or "(none installed)"
            raise PluginError(f"unknown {kind.value} plugin '{name}'; valid: {valid}") from None

    def find(self, text: str) -> PluginSpec:
        """The plugin named ``kind:name`` or ``name``; a one-line :class:`PluginError` for an
        unknown name, or a bare name that several kinds use (it lists the qualified ones)."""
        if ":" in text:
            kind, _, name = text.partition(":")
            valid_kinds = [k.value for k in PluginKind]
            if kind not in valid_kinds:
                raise PluginError(f"unknown plugin kind '{kind}' in '{text}'; valid: "
                                  f"{', '.join(valid_kinds)}")
            return self.get(kind, name)
        matches = [spec for spec in self.specs() if spec.name == text]
        if len(matches) == 1:
            return matches[0]
        if matches:
            raise PluginError(f"plugin name '{text}' is used by {len(matches)} kinds; give one "
                              f"of: {', '.join(s.qualified_name for s in matches)}")
        valid = ", ".join(s.qualified_name for s in self.specs()) or "(none installed)"
        raise PluginError(f"unknown plugin '{text}'; valid: {valid}")

    def names(self, kind: PluginKind | str) -> list[str]:
        kind = PluginKind(kind)
        return sorted(n for k, n in self._specs if k is kind)

    def specs(self, kind: PluginKind | str | None = None) -> list[PluginSpec]:
        if kind is None:
            return sorted(self._specs.values(), key=lambda s: (list(PluginKind).index(s.kind),
                                                               s.name))
        kind = PluginKind(kind)
        return [self._specs[(kind, n)] for n in self.names(kind)]

    @overload
    def create(self, kind: Literal[PluginKind.SIMULATOR, "simulator"], name: str,
               options: PluginOptions = None) -> Simulator: ...
    @overload
    def create(self, kind: Literal[PluginKind.PHASOR_TRANSFORM, "transform"], name: str,
               options: PluginOptions = None) -> PhasorTransform: ...
    @overload
    def create(self, kind: Literal[PluginKind.FIELD_MODEL, "model"], name: str,
               options: PluginOptions = None) -> FieldModel: ...
    @overload
    def create(self, kind: Literal[PluginKind.IMAGER, "imager"], name: str,
               options: PluginOptions = None) -> Imager: ...
    @overload
    def create(self, kind: Literal[PluginKind.CAPTURE_FORMAT, "capture_format"], name: str,
               options: PluginOptions = None) -> CaptureFormat: ...
    @overload
    def create(self, kind: PluginKind | str, name: str,
               options: PluginOptions = None) -> Configurable: ...

    def create(self, kind: PluginKind | str, name: str,
               options: PluginOptions = None) -> Configurable:
        """Plugin ``name`` of ``kind`` built with ``options`` (a mapping or a config
        instance): an instance of the kind's interface (a one-line PluginError otherwise)."""
        spec = self.get(kind, name)
        plugin = spec.create(options)
        interface = INTERFACES[spec.kind.value]
        if not isinstance(plugin, interface):
            raise PluginError(f"{spec.label} is not a {interface.__name__} (its factory made "
                              f"a {type(plugin).__name__})")
        if spec.kind is PluginKind.IMAGER:  # bound to the array backend its device selects
            from nlosfw.plugins.array_backends import bind_device
            return bind_device(plugin, self.array_backends)  # type: ignore[return-value]
        return plugin

    def __len__(self) -> int:
        return len(self._specs)

    def __contains__(self, key: tuple[PluginKind | str, str]) -> bool:
        kind, name = key
        return (PluginKind(kind), name) in self._specs


def registration_options(cls: type[T], options: Mapping[str, object], who: str) -> T:
    """The options dataclass ``cls`` of one ``register(...)`` call; a one-line
    :class:`PluginError` names an unknown or a missing option and the valid ones."""
    valid = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(options) - set(valid))
    required = [f.name for f in fields(cls) if f.default is MISSING]  # type: ignore[arg-type]
    missing = [n for n in required if n not in options]
    if unknown or missing:
        problem = (f"unknown option {unknown[0]!r}" if unknown
                   else f"no {missing[0]!r} (required: {', '.join(required)})")
        raise PluginError(f"{who} is registered with {problem}; valid: {', '.join(valid)}")
    return cls(**options)


@dataclass(frozen=True)
class RegistrationOptions:
    """The keyword options of ``register(name, factory, **options)`` (see :class:`PluginSpec`).

    ``requires`` lists importable modules the factory needs, or maps each to the pip
    requirement that provides it (``{"torch": "torch==2.13.0"}``).
    """

    config: str | type | None = None
    requires: Sequence[str] | Mapping[str, str] = ()
    description: str = ""
    test_config: Mapping[str, object] | None = None
    expected_failures: Mapping[str, str] | None = None
    capabilities: Iterable[str | Capability] | None = None
    """What the plugin can do, from its kind's vocabulary
    (:data:`nlosfw.plugins.capabilities.VOCABULARY`; a name outside it is a one-line
    :class:`PluginError`); ``None`` takes the kind's defaults. The conformance kit picks
    its checks from them."""
    system_check: str | None = None
    """``"module:function"`` returning '' or what to install outside Python, in one line."""


class RegistrationKwargs(TypedDict, total=False):
    """The keyword options of a ``register(name, factory, ...)`` call, typed (what they mean:
    :class:`RegistrationOptions`)."""

    config: str | type | None
    requires: Sequence[str] | Mapping[str, str]
    description: str
    test_config: Mapping[str, object] | None
    expected_failures: Mapping[str, str] | None
    capabilities: Iterable[str | Capability] | None
    system_check: str | None


@dataclass
class Registrar:
    """The ``register`` callable handed to ``register_*`` hooks of one plugin module."""

    kind: PluginKind
    distribution: str
    entry_point: str
    accept: Callable[[PluginSpec], bool]
    registry: Registry

    def __call__(self, name: str, factory: str | Callable[..., Any] | LazyFactory,
                 **options: Unpack[RegistrationKwargs]) -> None:
        """Register plugin ``name`` of this hook's kind, with :class:`RegistrationOptions`
        (an unknown option is a one-line :class:`PluginError`). Capabilities given here
        take the place of those the plugin's class declares."""
        if not name or not name.replace("_", "").replace("-", "").isalnum():
            raise PluginError(f"{self.distribution}: invalid {self.kind.value} plugin name "
                              f"{name!r}; use letters, digits, '_' and '-'")
        opts = registration_options(RegistrationOptions, options,
                                    f"{self.distribution}: {self.kind.value} plugin {name!r}")
        if isinstance(opts.requires, Mapping):
            reqs = tuple((str(m), str(r)) for m, r in opts.requires.items())
        else:
            reqs = tuple((str(m), str(m)) for m in opts.requires)
        spec = PluginSpec(
            kind=self.kind, name=name, factory=factory, distribution=self.distribution,
            entry_point=self.entry_point, config=opts.config, requires=reqs,
            description=opts.description, test_config=dict(opts.test_config or {}),
            expected_failures=dict(opts.expected_failures or {}),
            declared_capabilities=(None if opts.capabilities is None
                                   else _as_tuple(opts.capabilities, self.kind,
                                                  f"{self.distribution}: {self.kind.value} "
                                                  f"plugin '{name}'")),
            system_check=opts.system_check,
        )
        if self.accept(spec):
            self.registry.add(spec)


def _as_tuple(capabilities: Iterable[str | Capability], kind: PluginKind, who: str
              ) -> tuple[str, ...]:
    """A tuple of the declared names; a single name instead of a list is a one-line
    :class:`PluginError` (from :func:`parse_capabilities`)."""
    if isinstance(capabilities, str) or not isinstance(capabilities, Iterable):
        parse_capabilities(kind, who, capabilities)
    return tuple(capabilities)


def _reason(err: Exception) -> str:
    """An import failure in one line: ImportError's own message, else the type and message."""
    if isinstance(err, ImportError):
        return str(err)
    return f"{type(err).__name__}: {err}"


def _quote(requirement: str) -> str:
    return f"'{requirement}'" if any(c in requirement for c in "<>=!~ ;[") else requirement

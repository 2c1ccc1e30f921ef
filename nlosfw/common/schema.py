"""The OmegaConf schema of a config dataclass, and OmegaConf's errors as one-line ConfigErrors.

Every config in nlosfw is a frozen dataclass. OmegaConf (and so Hydra) checks names and
types against a dataclass, but turns a frozen one into read-only nodes that no override
can change; :func:`schema_class` therefore gives each config dataclass a mutable twin with
the same fields, types and defaults (nested configs replaced by their twins). Hydra's
ConfigStore holds these twins, so Hydra checks the command line against them as it
composes, and :func:`~nlosfw.common.config.config_from_mapping` checks a Python caller's
mapping against the same twin:

1. :func:`fill` writes a mapping into a schema node one value at a time, so that OmegaConf
   checks each name and type and a mistake names its exact option
   (``model.items[0].count``). On top of OmegaConf's rules, a bool must be written as a
   bool (OmegaConf would read ``"yes"`` or ``1`` as true), a whole float is accepted
   as an integer, and text is kept as written (a ``${...}`` in it is never resolved). A
   node Hydra composed is already checked and needs no filling;
2. :func:`build` turns a checked node into the frozen dataclass: it refuses options added
   with ``+key=value`` and NaN numbers, makes tuples (checking fixed lengths), and runs
   each dataclass's ``__post_init__`` range checks with the option's dotted name
   prefixed to their errors.

An option a config dataclass has renamed (its ``renamed_options``,
:func:`renamed_option`) is refused in one line that gives the new
name, wherever it is written: the command line, a preset, a Python mapping.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import math
import operator
import re
import threading
import types
from collections.abc import Mapping
from typing import Any, TypeGuard, Union, get_args, get_origin, get_type_hints

import numpy as np
from omegaconf import (
    MISSING,
    BooleanNode,
    DictConfig,
    EnumNode,
    FloatNode,
    IntegerNode,
    ListConfig,
    OmegaConf,
    StringNode,
)
from omegaconf.errors import (
    ConfigAttributeError,
    ConfigKeyError,
    MissingMandatoryValue,
    OmegaConfBaseException,
)

from nlosfw.common.errors import ConfigError
from nlosfw.common.text import omegaconf_literal

_NONE_TYPE = type(None)


# --------------------------------------------------------------------------- schemas
def schema_class(cls: type, name: str | None = None) -> type:
    """The mutable twin of config dataclass ``cls`` that OmegaConf and Hydra check against.

    With ``name``, the twin starts with a field ``name`` defaulting to it (a plugin's
    entry in its Hydra config group: ``model: {name: siren_torch, ...}``). The same
    arguments give the same class, in every thread: the twins are made under a lock (two
    threads making the same twin at once would each get a class of their own, and
    OmegaConf would then refuse one as "X is not a subclass of X").
    """
    with _TWINS_LOCK:
        return _twin(cls, name)


#: Held while twins are made (re-entrant: a twin's fields make the twins of theirs).
_TWINS_LOCK = threading.RLock()


@functools.cache
def _twin(cls: type, name: str | None) -> type:
    hints = get_type_hints(cls)
    specs: list[tuple[str, Any, Any]] = []
    if name is not None:
        specs.append(("name", str, dataclasses.field(default=name)))
    for f in dataclasses.fields(cls):
        if f.init:
            specs.append((f.name, _schema_type(hints[f.name]), _schema_default(f)))
    twin = dataclasses.make_dataclass(cls.__name__, specs, namespace={"schema_of": cls})
    twin.__doc__ = cls.__doc__
    # found again by pickle through this module's __getattr__ (Hydra's launchers pickle the
    # ConfigStore, which holds the twins, to start jobs in other processes)
    twin.__module__ = __name__
    twin.__qualname__ = (f"{cls.__qualname__.replace('.', ':')}@{cls.__module__.replace('.', '/')}"
                         + ("" if name is None else f"#{name}"))
    return twin


def __getattr__(qualname: str) -> type:
    """The twin named ``qualname`` by :func:`schema_class` (how pickle finds it again)."""
    cls_name, at, rest = qualname.partition("@")
    if not at:
        raise AttributeError(f"module {__name__!r} has no attribute {qualname!r}")
    module, _, name = rest.partition("#")
    cls: Any = importlib.import_module(module.replace("/", "."))
    for part in cls_name.split(":"):
        cls = getattr(cls, part)
    return schema_class(cls, name or None)


def schema_node(cls: type) -> DictConfig:
    """A fresh OmegaConf node of ``cls``'s schema holding its defaults."""
    try:
        return OmegaConf.structured(schema_class(cls))
    except OmegaConfBaseException as err:
        raise TypeError(f"{cls.__qualname__} cannot be used as a Hydra structured config: "
                        f"{_message(err)}") from None


def is_schema_node(value: Any, cls: type) -> TypeGuard[DictConfig]:
    """Whether ``value`` is a node Hydra or OmegaConf made from the schema of ``cls``."""
    if not isinstance(value, DictConfig):
        return False
    schema_of = getattr(OmegaConf.get_type(value), "schema_of", None)
    return isinstance(schema_of, type) and issubclass(schema_of, cls)


def _schema_type(tp: Any) -> Any:
    """``tp`` with every config dataclass in it replaced by its schema twin."""
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return schema_class(tp)
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        return functools.reduce(operator.or_, [_schema_type(a) for a in args])
    if origin in (tuple, list, dict) and args:
        return origin[tuple(a if a is Ellipsis else _schema_type(a) for a in args)]
    return tp


def _schema_default(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:
        factory = f.default_factory
        return dataclasses.field(default_factory=lambda: _schema_value(factory()))
    if f.default is dataclasses.MISSING:
        return dataclasses.field(default=MISSING)
    if dataclasses.is_dataclass(f.default):
        default = f.default
        return dataclasses.field(default_factory=lambda: _schema_value(default))
    return dataclasses.field(default=f.default)


def _schema_value(value: Any) -> Any:
    """A config value with its dataclass instances replaced by instances of their twins."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        twin = schema_class(type(value))
        return twin(**{f.name: _schema_value(getattr(value, f.name))
                       for f in dataclasses.fields(value) if f.init})
    if isinstance(value, Mapping):
        return {k: _schema_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_schema_value(v) for v in value)
    return value


# --------------------------------------------------------------------------- filling
def fill(node: DictConfig, mapping: Mapping[str, Any], where: str) -> None:
    """Write ``mapping`` into the schema ``node``, merging into sub-mappings, replacing lists."""
    for key, value in mapping.items():
        _put(node, str(key), value, _join(where, str(key)))


def _put(parent: Any, key: Any, value: Any, where: str) -> None:
    """Write ``value`` at ``key`` of ``parent`` (a DictConfig; a ListConfig: its next index)."""
    value = _plain_input(value)
    if isinstance(value, Mapping):
        if not isinstance(_child(parent, key), DictConfig):
            _set(parent, key, {}, where, value)
        child = parent[key]
        for k, v in value.items():
            _put(child, str(k), v, f"{where}.{k}")
    elif isinstance(value, (list, tuple, ListConfig, np.ndarray)):
        items = [_plain_input(v) for v in value]
        mappings = bool(items) and all(isinstance(v, Mapping) for v in items)
        # a list of mappings is merged as default elements (of the list's element type)
        # that each mapping then fills; other lists are filled by appending each value
        _set(parent, key, [{}] * len(items) if mappings else [], where, value)
        child = parent[key]
        for i, item in enumerate(items):
            _put(child, i, item, f"{where}[{i}]")
    else:
        # a mapping's text is data: stored escaped, so that reading it back never resolves
        # an interpolation in it (``${oc.env:NAME}`` in a file name or a scene's name)
        stored = omegaconf_literal(value) if isinstance(value, str) and "${" in value \
            else value
        _set(parent, key, stored, where, value)
        kind = OmegaConf.get_type(parent, key)   # or a list index
        if kind is bool and not isinstance(value, bool):
            raise ConfigError(where, f"must be true or false, got {_describe(value)}")


def _plain_input(value: Any) -> Any:
    """A config dataclass instance as its mapping, a numpy scalar as a Python scalar."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value) if f.init}
    if isinstance(value, np.generic):
        return value.item()
    return value


def _child(parent: Any, key: Any) -> Any:
    if isinstance(parent, ListConfig):
        return parent[key] if isinstance(key, int) and key < len(parent) else None
    return parent.get(key)


def _set(parent: Any, key: Any, value: Any, where: str, given: Any) -> None:
    """Put ``value`` at ``key`` (appending to a list) as OmegaConf merges it into a config."""
    try:
        try:
            if isinstance(parent, ListConfig):
                parent.append(value)
            elif isinstance(value, (dict, list)):
                parent.merge_with({key: value})     # makes elements of a list's element type
            else:
                parent[key] = value
        except OmegaConfBaseException as err:
            if not (isinstance(err.child_node, IntegerNode) and _is_whole_float(value)):
                raise
            _set(parent, key, int(value), where, given)     # 2.0 is the integer 2
    except (ConfigKeyError, ConfigAttributeError):
        raise ConfigError(where, renamed(parent, str(key), where, given)
                          or f"unknown option; valid options: {_keys(parent)}") from None
    except OmegaConfBaseException as err:
        raise ConfigError(where, renamed(parent, str(key), where, given)
                          or problem(err, given)) from None


# --------------------------------------------------------------------------- building
def build(cls: type, node: DictConfig, where: str) -> Any:
    """The frozen dataclass ``cls`` from a node checked against its schema.

    ``node`` may be the schema of a subclass of ``cls`` (or a plugin's group entry, which
    adds ``name``): fields of that schema that ``cls`` lacks are ignored, keys it lacks
    (added with ``+key=value``) are refused.
    """
    fields = [f for f in dataclasses.fields(cls) if f.init]
    schema = OmegaConf.get_type(node)
    known = {f.name for f in dataclasses.fields(schema if dataclasses.is_dataclass(schema)
                                                else cls)}
    for key in node:
        if str(key) not in known:
            valid = ", ".join(sorted(f.name for f in fields)) or "(none)"
            option = _join(where, str(key))
            raise ConfigError(option, renamed(node, str(key), option)
                              or f"unknown option; valid options: {valid}")
    hints = get_type_hints(cls)
    kwargs = {f.name: _python(_value(node, f.name, where), hints[f.name], _join(where, f.name))
              for f in fields}
    try:
        return cls(**kwargs)
    except ConfigError as err:
        raise (err.within(where) if where else err) from None


def _value(node: Any, key: Any, where: str) -> Any:
    """``node[key]`` with interpolations resolved; a missing value is a one-line error."""
    try:
        return node[key]
    except MissingMandatoryValue:
        raise ConfigError(_join(where, str(key)), "is required") from None
    except OmegaConfBaseException as err:
        raise ConfigError(_join(where, str(key)), problem(err, err.value)) from None


def _python(value: Any, tp: Any, where: str) -> Any:
    """``value`` (a node's content) as the Python value of annotation ``tp``."""
    if value is None:
        return None
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        (tp,) = [a for a in args if a is not _NONE_TYPE] or [Any]
        origin, args = get_origin(tp), get_args(tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return build(tp, value, where)
    if tp is float and isinstance(value, float) and math.isnan(value):
        raise ConfigError(where, "must be a number, got NaN")
    if origin in (tuple, list):
        fixed = origin is tuple and bool(args) and args[-1] is not Ellipsis
        if fixed and len(value) != len(args):
            raise ConfigError(where, f"must be a list of {len(args)} values, got "
                                     f"{len(value)} values")
        items = [_python(_value(value, i, where), args[i] if fixed else (args[0] if args
                                                                        else Any),
                         f"{where}[{i}]") for i in range(len(value))]
        return tuple(items) if origin is tuple else items
    if origin is dict and len(args) == 2 and isinstance(args[1], type) \
            and dataclasses.is_dataclass(args[1]):
        return {str(k): build(args[1], _value(value, k, where), _join(where, str(k)))
                for k in value}
    if isinstance(value, (DictConfig, ListConfig)):
        return OmegaConf.to_container(value, resolve=True)
    return value


# --------------------------------------------------------------------------- errors
def renamed_option(cls: type, name: str) -> str | None:
    """The name option ``name`` of config dataclass ``cls`` has now, if it was renamed (the
    class's ``renamed_options``: old name -> new dotted name, e.g. ``depth_range`` ->
    ``depth.range``), else None. An option that became a group of the same name
    (``lobe`` -> ``lobe.exponent``) counts when it is given a plain value."""
    table: Mapping[str, str] = getattr(cls, "renamed_options", None) or {}
    return table.get(name)


def renamed(parent: object, key: str, where: str, value: object = None) -> str | None:
    """The refusal of option ``key`` of the schema node ``parent`` (written at the dotted
    ``where``) when its config renamed it: the name to write instead; None otherwise. An
    option that became a group of the same name counts only when given a plain value."""
    if not isinstance(parent, DictConfig):
        return None
    schema_of = getattr(OmegaConf.get_type(parent), "schema_of", None)
    new = renamed_option(schema_of, key) if isinstance(schema_of, type) else None
    if new is None:
        return None
    prefix = where[:-len(key)] if where.endswith(key) else ""
    if new.startswith(f"{key}."):
        if isinstance(value, (Mapping, DictConfig)):
            return None
        return (f"is a group of options now; write {prefix}{new} (the option it was) or "
                f"{prefix}{key}.<option>")
    return f"was renamed; write {prefix}{new} instead"


def problem(err: OmegaConfBaseException, value: Any) -> str:
    """What is wrong, in words, for OmegaConf's error ``err`` about ``value``."""
    if isinstance(err, MissingMandatoryValue):
        return "is required"
    if err.key is not None and err.full_key:
        moved = renamed(err.parent_node, str(err.key), str(err.full_key), value)
        if moved is not None:
            return moved
    if isinstance(err, (ConfigKeyError, ConfigAttributeError)) and isinstance(
            err.parent_node, DictConfig):
        if not dataclasses.is_dataclass(OmegaConf.get_type(err.parent_node)):
            return "not in the config (to add it, start the override with +)"
        return f"unknown option; valid options: {_keys(err.parent_node)}"
    message = _message(err)
    expected = _expected_of_node(err.child_node) or _expected_of_message(message)
    if expected is not None:
        enum_value = isinstance(err.child_node, EnumNode) and value is not None
        return f"{expected}, got {repr(value) if enum_value else _describe(value)}"
    if "is not a DictConfig" in message or "merge ListConfig with DictConfig" in message:
        return f"expected a mapping of options, got {_describe(value)}"
    if "is not a ListConfig" in message or "merge DictConfig with ListConfig" in message:
        return f"must be a list, got {_describe(value)}"
    if "is not Optional" in message:
        return "must not be null"
    return message


def _expected_of_node(node: Any) -> str | None:
    if isinstance(node, EnumNode):
        return "must be one of " + ", ".join(repr(m.value) for m in node.enum_type)
    for node_type, words in ((BooleanNode, "must be true or false"),
                             (IntegerNode, "must be an integer"),
                             (FloatNode, "must be a number"),
                             (StringNode, "must be a string")):
        if isinstance(node, node_type):
            return words
    if isinstance(node, ListConfig):
        return "must be a list"
    return None


def _expected_of_message(message: str) -> str | None:
    """The expected type named in OmegaConf's message (for list items, which lack a node)."""
    words = {"float": "must be a number", "int": "must be an integer",
             "bool": "must be true or false", "str": "must be a string"}
    match = re.search(r"could not be converted to (\w+)|is not a subclass of (\w+)", message)
    if match is None:
        return None
    name = match.group(1) or match.group(2)
    aliases = {"Float": "float", "Integer": "int", "Boolean": "bool", "String": "str"}
    return words.get(aliases.get(name, name), "expected a mapping of options")


# --------------------------------------------------------------------------- helpers
def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _message(err: OmegaConfBaseException) -> str:
    """The first line of OmegaConf's message (without its key and type context)."""
    lines = str(err.msg or err).strip().splitlines()
    return lines[0] if lines else type(err).__name__


def _keys(node: Any) -> str:
    return ", ".join(sorted(str(k) for k in node)) or "(none)"


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, (DictConfig, ListConfig)):
        value = OmegaConf.to_container(value)
    text = repr(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{text} ({type(value).__name__})"


def _is_whole_float(value: Any) -> bool:
    return isinstance(value, float) and value.is_integer()

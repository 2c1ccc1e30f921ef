"""Typed configuration dataclasses to and from plain mappings.

Plugins and scenes describe their options as (frozen) dataclasses. Hydra and
YAML hand us plain mappings; :func:`config_from_mapping` turns one into the
other, checking every name and type so that a mistake produces one line naming
the option and what would be valid. :func:`config_to_dict` goes back.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import types
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from nlosfw.common.errors import ConfigError

T = TypeVar("T")

_NONE_TYPE = type(None)


def config_from_mapping(cls: type[T], mapping: Mapping[str, Any] | None, where: str = "") -> T:
    """Build the dataclass ``cls`` from ``mapping``, validating names and types.

    Missing keys take the dataclass defaults. ``where`` is the dotted prefix used
    in error messages (``"model"`` gives ``model.lr: ...``).
    """
    if mapping is None:
        mapping = {}
    if isinstance(mapping, cls):
        return mapping
    if not isinstance(mapping, Mapping):
        raise ConfigError(where, f"expected a mapping of options, got {_describe(mapping)}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        valid = ", ".join(sorted(fields)) or "(none)"
        raise ConfigError(_join(where, str(unknown[0])), f"unknown option; valid options: {valid}")
    hints = get_type_hints(cls)
    kwargs = {}
    for name, value in mapping.items():
        kwargs[name] = _coerce(value, hints[name], _join(where, name))
    missing = [
        n for n, f in fields.items()
        if n not in kwargs
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise ConfigError(_join(where, missing[0]), "is required")
    try:
        return cls(**kwargs)
    except ConfigError as err:
        raise err.within(where) if where else err from None


def config_to_dict(config: Any) -> dict[str, Any]:
    """A plain, YAML-safe dict of a config dataclass (enums become their values)."""
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"expected a dataclass instance, got {type(config).__name__}")
    return {f.name: _plain(getattr(config, f.name)) for f in dataclasses.fields(config)}


def config_defaults(cls: type) -> dict[str, Any]:
    """The plain dict of ``cls()``'s defaults (every field must have one)."""
    return config_to_dict(cls())


def require(condition: bool, option: str, problem: str) -> None:
    """Raise :class:`ConfigError` for ``option`` unless ``condition`` holds.

    Meant for ``__post_init__`` range checks of config dataclasses.
    """
    if not condition:
        raise ConfigError(option, problem)


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return config_to_dict(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _describe(value: Any) -> str:
    text = repr(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{text} ({type(value).__name__})"


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in get_args(tp))
    if tp is _NONE_TYPE:
        return "null"
    if origin in (tuple, list, Sequence):
        args = get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            return f"a list of {len(args)} values"
        return "a list"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return "one of " + ", ".join(repr(m.value) for m in tp)
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    return getattr(tp, "__name__", str(tp))


def _coerce(value: Any, tp: Any, where: str) -> Any:
    """Convert ``value`` to the annotated type ``tp`` or raise ConfigError."""
    if tp is Any:
        return _plain_container(value)
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None:
            if _NONE_TYPE in args:
                return None
            raise ConfigError(where, f"must be {_type_name(tp)}, got null")
        errors = []
        for arg in args:
            if arg is _NONE_TYPE:
                continue
            try:
                return _coerce(value, arg, where)
            except ConfigError as err:
                errors.append(err)
        if len(errors) == 1:
            raise errors[0]
        raise ConfigError(where, f"must be {_type_name(tp)}, got {_describe(value)}")
    if origin is Literal:
        choices = get_args(tp)
        if value in choices:
            return value
        raise ConfigError(where, f"must be {_type_name(tp)}, got {value!r}")
    if dataclasses.is_dataclass(tp):
        return config_from_mapping(tp, value, where)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            if isinstance(value, str) and value.upper() in tp.__members__:
                return tp[value.upper()]
            raise ConfigError(where, f"must be {_type_name(tp)}, got {value!r}") from None
    if origin in (tuple, list) or tp in (tuple, list):
        return _coerce_sequence(value, tp, where)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(where, f"must be a mapping, got {_describe(value)}")
        args = get_args(tp)
        vtype = args[1] if len(args) == 2 else Any
        return {str(k): _coerce(v, vtype, f"{where}.{k}") for k, v in value.items()}
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(where, f"must be true or false, got {_describe(value)}")
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                return int(value)
            raise ConfigError(where, f"must be an integer, got {_describe(value)}")
        return int(value)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(where, f"must be a number, got {_describe(value)}")
        value = float(value)
        if math.isnan(value):
            raise ConfigError(where, "must be a number, got NaN")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(where, f"must be a string, got {_describe(value)}")
        return value
    return value


def _coerce_sequence(value: Any, tp: Any, where: str) -> tuple:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        if not _is_sequence_like(value):
            raise ConfigError(where, f"must be {_type_name(tp)}, got {_describe(value)}")
        value = list(value)
    args = get_args(tp)
    if not args:
        return tuple(value)
    if get_origin(tp) is tuple and args[-1] is not Ellipsis:
        if len(value) != len(args):
            raise ConfigError(where, f"must be {_type_name(tp)}, got {len(value)} values")
        pairs = enumerate(zip(value, args, strict=True))
        return tuple(_coerce(v, a, f"{where}[{i}]") for i, (v, a) in pairs)
    item_type = args[0]
    return tuple(_coerce(v, item_type, f"{where}[{i}]") for i, v in enumerate(value))


def _is_sequence_like(value: Any) -> bool:
    # OmegaConf ListConfig is a Sequence; numpy arrays are not registered as one.
    return hasattr(value, "__len__") and hasattr(value, "__iter__") and not isinstance(
        value, (str, bytes, Mapping)
    )


def _plain_container(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain_container(v) for k, v in value.items()}
    if _is_sequence_like(value):
        return [_plain_container(v) for v in value]
    return value


class Configurable:
    """Base of every plugin: holds a validated, immutable config instance of ``config_class``."""

    config_class: ClassVar[type] = object

    def __init__(self, config: Any = None) -> None:
        self.config = config_from_mapping(self.config_class, config)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({config_to_dict(self.config)})"

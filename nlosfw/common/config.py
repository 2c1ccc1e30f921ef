"""Typed configuration dataclasses to and from plain mappings.

Plugins and scenes describe their options as frozen dataclasses, their choices as
:class:`Choice` enums. Hydra and YAML hand us plain mappings; :func:`config_from_mapping`
checks one against the dataclass's OmegaConf schema (the same schema Hydra composes the
command line against, see :mod:`nlosfw.common.schema`), so that a mistake produces one
line naming the option and what would be valid. :func:`config_to_dict` goes back.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import operator
from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Generic, SupportsFloat, TypeVar

from nlosfw.common.errors import ConfigError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T")

#: A plain scalar value: of a config option, a metric, a table cell.
Scalar = str | int | float | bool | None
C = TypeVar("C", bound="DataclassInstance")


class Choice(str, enum.Enum):
    """Base of the choice options of config dataclasses (``class Combine(Choice)``).

    Members are named as their values (``coherent = "coherent"``): OmegaConf matches enum
    options by member name, so YAML and the command line write the value. A member is a
    ``str`` equal to its value and prints as it.
    """

    def __str__(self) -> str:
        return str(self.value)


def config_from_mapping(cls: type[T], mapping: T | Mapping[str, object] | None,
                        where: str = "") -> T:
    """Build the dataclass ``cls`` from ``mapping``, validating names, types and ranges.

    Missing keys take the dataclass defaults; an instance of ``cls`` is returned as is, and
    a node Hydra composed against ``cls``'s schema is taken as already checked by it.
    ``where`` is the dotted prefix used in error messages (``"model"`` gives
    ``model.lr: ...``).
    """
    from nlosfw.common.schema import build, fill, is_schema_node, schema_node

    if mapping is None:
        mapping = {}
    if isinstance(mapping, cls):
        return mapping
    if not isinstance(mapping, Mapping):
        raise ConfigError(where, f"expected a mapping of options, got {mapping!r} "
                                 f"({type(mapping).__name__})")
    if is_schema_node(mapping, cls):
        return build(cls, mapping, where)
    node = schema_node(cls)
    fill(node, mapping, where)
    return build(cls, node, where)


def with_current_names(cls: type, mapping: Mapping[str, object]) -> dict[str, object]:
    """``mapping`` (options of config dataclass ``cls``) with the options renamed since
    (:func:`~nlosfw.common.schema.renamed_option`) moved to their new names, groups made as
    needed: how a file written before a rename (a saved model's config) still loads. Other
    options are kept; a group given as a mapping is taken as it is."""
    from nlosfw.common.schema import renamed_option

    out: dict[str, object] = {}
    for key, value in mapping.items():
        new = renamed_option(cls, str(key))
        if new is None or (isinstance(value, Mapping) and new.startswith(f"{key}.")):
            path = [str(key)]
        else:
            path = new.split(".")
        node = out
        for part in path[:-1]:
            child = node.get(part)
            if not isinstance(child, dict):
                child = node[part] = {} if not isinstance(child, Mapping) else dict(child)
            node = child
        last = node.get(path[-1])
        if isinstance(last, dict) and isinstance(value, Mapping):
            last.update(value)
        else:
            node[path[-1]] = dict(value) if isinstance(value, Mapping) else value
    return out


def config_to_dict(config: DataclassInstance) -> dict[str, Any]:
    """A plain, YAML-safe dict of a config dataclass (enums become their values)."""
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"expected a dataclass instance, got {type(config).__name__}")
    return {f.name: _plain(getattr(config, f.name)) for f in dataclasses.fields(config)}


def number(value: object) -> float:
    """A plain value (of a config, of metadata) as a float; TypeError unless it is a real
    number or a numeric string."""
    if not isinstance(value, (str, SupportsFloat)):
        raise TypeError(f"not a number: {value!r}")
    return float(value)


def require(condition: bool, option: str, problem: str) -> None:
    """Raise :class:`ConfigError` for ``option`` unless ``condition`` holds.

    Meant for ``__post_init__`` range checks of config dataclasses.
    """
    if not condition:
        raise ConfigError(option, problem)


#: The largest seed an option may hold: seeds feed numpy's generators (any integer >= 0),
#: torch (below 2^64) and JAX's keys (int64); every seed is an integer 0 to 2^63 - 1.
MAX_SEED = 2**63 - 1


def is_seed(value: object) -> bool:
    """Whether ``value`` is a seed: an integer (Python's or numpy's) from 0 to
    :data:`MAX_SEED`."""
    if isinstance(value, bool):
        return False
    try:
        number = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        return False
    return 0 <= number <= MAX_SEED


def require_seed(value: object, option: str) -> None:
    """Raise :class:`ConfigError` for ``option`` unless ``value`` is a seed (a negative one
    ended numpy's generators, a larger one JAX's keys, after the run had started)."""
    if not is_seed(value):
        raise ConfigError(option, f"must be an integer from 0 to {MAX_SEED}, got {value!r}")


#: The most threads a ``workers`` or ``threads`` option may ask for: thread pools and the C
#: libraries they are handed to take a C int (10^20 ended a run in scipy's FFT), and no
#: machine has as many cores.
MAX_THREADS = 4096


def require_threads(value: int, option: str, auto: int, meaning: str) -> None:
    """Raise :class:`ConfigError` for ``option`` unless ``value`` is ``auto`` (-1 or 0, which
    means ``meaning``: all cores, the library's default) or a thread count from 1 to
    :data:`MAX_THREADS`."""
    if value != auto and not 1 <= value <= MAX_THREADS:
        raise ConfigError(option, f"must be {auto} ({meaning}) or 1 to {MAX_THREADS}, got "
                                  f"{value}")


def require_finite(config: DataclassInstance) -> None:
    """Raise :class:`ConfigError` for the first number of ``config`` (a dataclass instance;
    its own fields and tuples of numbers, not nested configs) that is NaN or infinite.

    Call it first in ``__post_init__``: comparisons with NaN are false, so range checks
    alone let it through.
    """
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        values = value if isinstance(value, (tuple, list)) else (value,)
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            raise ConfigError(f.name, f"must be finite, got {value}")


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


class Configurable(Generic[C]):
    """Base of every plugin: holds a validated, immutable config instance of ``config_class``.

    A plugin class states its config type as the parameter (``class Mine(FieldModel[MyConfig])``,
    so ``self.config`` is a ``MyConfig``) and may declare what it can do in ``capabilities``
    (names from its kind's vocabulary, :data:`nlosfw.plugins.capabilities.VOCABULARY`; ``None``:
    the kind's defaults), which the registry and the conformance kit read.
    """

    config_class: ClassVar[type] = object
    capabilities: ClassVar[Collection[str] | None] = None

    def __init__(self, config: C | Mapping[str, object] | None = None) -> None:
        self.config: C = config_from_mapping(self.config_class, config)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({config_to_dict(self.config)})"

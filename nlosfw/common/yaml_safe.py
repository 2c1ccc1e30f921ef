"""YAML for metadata: plain safe YAML out; safe YAML plus y-tal's numpy tags in.

y-tal dumps ``scene_info`` with PyYAML's full dumper, so numpy arrays appear as
``!!python/object/apply:numpy...`` nodes. :func:`load` accepts exactly those
numpy constructions (arrays, dtypes, scalars) from a whitelist and nothing else:
no arbitrary Python object is ever built from a file. It also bounds what a file can
make it build: the text's size, the nesting depth, and the number of values once every
alias is expanded (an "alias bomb" of a few hundred bytes otherwise expands to gigabytes
when the result is copied or written out); :class:`LimitExceeded` says which.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np
import yaml

#: Limits of :func:`load`: characters of text, nesting depth, values with aliases expanded.
MAX_CHARACTERS = 128_000_000
MAX_DEPTH = 100
MAX_VALUES = 5_000_000

_APPLY = "tag:yaml.org,2002:python/object/apply:"
_NAME = "tag:yaml.org,2002:python/name:"


def _numpy_attr(dotted: str) -> Any:
    """Resolve a whitelisted numpy callable, across numpy 1 (numpy.core) and 2 (numpy._core)."""
    allowed = {
        "numpy.core.multiarray._reconstruct": ("_reconstruct",),
        "numpy._core.multiarray._reconstruct": ("_reconstruct",),
        "numpy.core.multiarray.scalar": ("scalar",),
        "numpy._core.multiarray.scalar": ("scalar",),
        "numpy.dtype": ("dtype",),
        "numpy.ndarray": ("ndarray",),
    }
    if dotted not in allowed:
        raise yaml.constructor.ConstructorError(None, None, f"refusing to build {dotted} from YAML")
    name = allowed[dotted][0]
    if name in ("dtype", "ndarray"):
        return getattr(np, name)
    try:
        multiarray = importlib.import_module("numpy._core.multiarray")  # numpy >= 2
    except ImportError:  # pragma: no cover - numpy 1
        multiarray = importlib.import_module("numpy.core.multiarray")
    return getattr(multiarray, name)


class LimitExceeded(yaml.YAMLError):
    """The YAML is refused: too long, too deeply nested, or its aliases expand too far."""


class _Loader(yaml.SafeLoader):
    """Safe YAML with y-tal's numpy nodes, nesting depth and alias expansion bounded."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise LimitExceeded(f"nested more than {MAX_DEPTH} levels deep")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_document(self) -> yaml.Node | None:
        node = super().compose_document()
        _check_expansion(node)
        return node


def _check_expansion(root: yaml.Node | None) -> None:
    """Refuse a node graph that is cyclic, or has more than MAX_VALUES values (or more than
    MAX_DEPTH levels) once its aliases (shared nodes) are expanded."""
    if root is None:
        return
    size: dict[int, int] = {}
    height: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        children = _children(node)
        if done:
            on_path.discard(key)
            size[key] = 1 + sum(size[id(c)] for c in children)
            height[key] = 1 + max((height[id(c)] for c in children), default=0)
            if size[key] > MAX_VALUES:
                raise LimitExceeded(f"its aliases expand to more than {MAX_VALUES:,} values "
                                    "(an alias bomb?)")
            if height[key] > MAX_DEPTH:
                raise LimitExceeded(f"its aliases expand to more than {MAX_DEPTH} levels of "
                                    "nesting")
            continue
        if key in size:
            continue
        if key in on_path:
            raise LimitExceeded("an alias refers to a node that contains it (a recursive "
                                "structure)")
        on_path.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in children if id(c) not in size)


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _construct_tuple(loader: yaml.SafeLoader, node: yaml.Node) -> tuple:
    if not isinstance(node, yaml.SequenceNode):
        raise yaml.constructor.ConstructorError(None, None, "a python/tuple must be a sequence")
    return tuple(loader.construct_sequence(node, deep=True))


def _construct_name(loader: yaml.SafeLoader, suffix: str, node: yaml.Node) -> Any:
    return _numpy_attr(suffix)


def _construct_apply(loader: yaml.SafeLoader, suffix: str, node: yaml.Node) -> Any:
    func = _numpy_attr(suffix)
    if isinstance(node, yaml.SequenceNode):
        args, state = loader.construct_sequence(node, deep=True), None
    elif isinstance(node, yaml.MappingNode):
        value = loader.construct_mapping(node, deep=True)
        args, state = value.get("args", []), value.get("state")
    else:
        raise yaml.constructor.ConstructorError(None, None, f"python/object/apply:{suffix} "
                                                "needs a sequence or a mapping")
    if suffix.endswith("scalar"):  # scalar(dtype, bytes)
        dtype, data = args
        if isinstance(data, str):
            data = data.encode("latin-1")
        return np.frombuffer(data, dtype=dtype)[0]
    obj = func(*args)
    if state is not None:
        if isinstance(obj, np.ndarray) and isinstance(state[-1], str):
            state = (*state[:-1], state[-1].encode("latin-1"))
        obj.__setstate__(state)
    return obj


_Loader.add_constructor("tag:yaml.org,2002:python/tuple", _construct_tuple)
_Loader.add_multi_constructor(_NAME, _construct_name)
_Loader.add_multi_constructor(_APPLY, _construct_apply)


def load(text: str | bytes) -> Any:
    """Parse YAML that may hold y-tal's numpy nodes; refuses any other Python object, and
    raises :class:`LimitExceeded` beyond the limits above."""
    if len(text) > MAX_CHARACTERS:
        raise LimitExceeded(f"longer than {MAX_CHARACTERS:,} characters")
    if isinstance(text, bytes):
        text = text.decode("utf-8")
    return yaml.load(text, Loader=_Loader)


def to_plain(value: Any) -> Any:
    """Numpy arrays and scalars to lists and Python numbers, recursively."""
    if isinstance(value, dict):
        return {str(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "value") and hasattr(type(value), "__members__"):  # Enum
        return value.value
    return value


def dump(value: Any) -> str:
    """Plain, safe YAML (numpy converted to lists)."""
    return yaml.safe_dump(to_plain(value), sort_keys=False, default_flow_style=None, width=120)

"""YAML for metadata: plain safe YAML out; safe YAML plus y-tal's numpy tags in.

y-tal dumps ``scene_info`` with PyYAML's full dumper, so numpy arrays appear as
``!!python/object/apply:numpy...`` nodes. :func:`load` accepts exactly those
numpy constructions (arrays, dtypes, scalars) from a whitelist and nothing else:
no arbitrary Python object is ever built from a file.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np
import yaml

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


class _Loader(yaml.SafeLoader):
    pass


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
    """Parse YAML that may hold y-tal's numpy nodes; refuses any other Python object."""
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

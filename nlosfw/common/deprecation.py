"""Public names that moved or were renamed, still importable from where they were for one
minor version: reading one warns (:class:`DeprecationWarning`) and names its new place."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Mapping

#: The release that drops the old names (they were public in 0.1).
REMOVED_IN = "0.3"


def moved_names(module: str, moved: Mapping[str, str],
                fallback: Callable[[str], object] | None = None) -> Callable[[str], object]:
    """A module ``__getattr__`` (PEP 562) for ``module``'s old names: ``moved`` maps an old
    name to ``"new.module:new_name"``; reading it warns and returns the new object. Other
    names go to ``fallback`` (e.g. :func:`nlosfw.common.lazy.lazy_exports`'s), or are an
    AttributeError."""

    def __getattr__(name: str) -> object:
        target = moved.get(name)
        if target is None:
            if fallback is not None:
                return fallback(name)
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        new_module, _, new_name = target.partition(":")
        warnings.warn(f"{module}.{name} is deprecated and will be removed in nlosfw "
                      f"{REMOVED_IN}: use {new_module}.{new_name}", DeprecationWarning,
                      stacklevel=2)
        return getattr(importlib.import_module(new_module), new_name)

    return __getattr__

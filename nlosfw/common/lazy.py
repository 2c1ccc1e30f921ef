"""A package's public names, imported on first use (PEP 562).

A package lists its names as usual, but inside ``if TYPE_CHECKING:`` (so type checkers
and readers see the imports), and ends with
``__getattr__, __dir__ = lazy_exports(__name__, __file__)``: each name then imports its
module when first read, so importing the package imports nothing else.
"""

from __future__ import annotations

import ast
import importlib
import sys
import types
from collections.abc import Callable
from pathlib import Path


def lazy_exports(package: str, init_file: str) -> tuple[Callable[[str], object],
                                                        Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``, whose ``__init__`` (``init_file``)
    imports its public names under ``if TYPE_CHECKING:``."""
    origins: dict[str, tuple[str, str]] = {}
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"))
    for block in tree.body:
        if isinstance(block, ast.If) and ast.unparse(block.test) == "TYPE_CHECKING":
            for stmt in block.body:
                if isinstance(stmt, ast.ImportFrom) and stmt.module:
                    for alias in stmt.names:
                        origins[alias.asname or alias.name] = (stmt.module, alias.name)

    def __getattr__(name: str) -> object:
        if name not in origins:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, attribute = origins[name]
        value: object = getattr(importlib.import_module(module), attribute)
        setattr(sys.modules[package], name, value)   # found directly from now on
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *origins})

    shadowed = {name for name, (module, _) in origins.items() if module == f"{package}.{name}"}
    if shadowed:   # a name that is also a submodule's: the name wins, as with eager imports
        sys.modules[package].__class__ = _keeping(frozenset(shadowed))
    return __getattr__, __dir__


def _keeping(names: frozenset[str]) -> type[types.ModuleType]:
    """A module class that does not let the import system bind submodules over ``names``."""

    class Package(types.ModuleType):
        def __setattr__(self, name: str, value: object) -> None:
            if not (name in names and isinstance(value, types.ModuleType)):
                super().__setattr__(name, value)

    return Package

"""docs/architecture.md describes the tree as it is: its package list names every package
of nlosfw/ and nothing that does not exist, each module it names lives in the package it is
described under, and what it says crosses each arrow is a typed, frozen object exported
where it says."""

from __future__ import annotations

import dataclasses
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "nlosfw"
DOC = ROOT / "docs" / "architecture.md"

#: A package's entry in the list: ``**`nlosfw.x`**:`` at a paragraph's or a bullet's start.
ENTRY = re.compile(r"^(?:- )?\*\*`(nlosfw(?:\.\w+)*)`\*\*", re.MULTILINE)


def _section(title: str) -> str:
    text = DOC.read_text(encoding="utf-8")
    assert f"\n## {title}\n" in text, f"docs/architecture.md has no section '## {title}'"
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def _entries() -> dict[str, str]:
    """Each package (or top-level module) the package list describes, with its text."""
    section = _section("The packages")
    starts = list(ENTRY.finditer(section))
    return {m.group(1): section[m.start():(starts[i + 1].start() if i + 1 < len(starts)
                                          else len(section))]
            for i, m in enumerate(starts)}


def _packages() -> set[str]:
    return {".".join(("nlosfw", *init.parent.relative_to(CORE).parts))
            for init in CORE.rglob("__init__.py")}


def test_the_package_list_names_every_package_and_only_real_ones():
    named = set(_entries())
    packages = _packages() - {"nlosfw"}        # the whole document describes the root
    missing = sorted(packages - named)
    assert not missing, f"docs/architecture.md's package list does not describe {missing}"
    modules = {".".join(p.relative_to(ROOT).with_suffix("").parts) for p in CORE.glob("*.py")}
    unknown = sorted(named - packages - modules)
    assert not unknown, f"docs/architecture.md describes packages that do not exist: {unknown}"


def test_every_module_named_lives_in_its_package():
    wrong = []
    for name, text in _entries().items():
        folder = ROOT.joinpath(*name.split("."))
        if not folder.is_dir():                       # a top-level module (nlosfw.api)
            continue
        # the model package's entry ends where its families' bullets begin
        wrong += [f"{name}: {module}" for module in re.findall(r"`(\w+\.py)`", text)
                  if not (folder / module).is_file()]
    assert not wrong, f"docs/architecture.md names modules that are not there: {wrong}"


def _arrows() -> list[tuple[str, str, str]]:
    """(arrow, type name, package) for each type the 'what crosses each arrow' table names."""
    lines = [line for line in _section("The picture").splitlines() if line.startswith("|")]
    assert len(lines) > 5, "docs/architecture.md's table of what crosses each arrow is gone"
    found = []
    for line in lines[2:]:
        arrow, objects, where = (cell.strip() for cell in line.strip().strip("|").split("|"))
        package = re.fullmatch(r"`([\w.]+)`", where)
        assert package, f"the table's 'where defined' is not one module: {line}"
        found += [(arrow, name, package.group(1)) for name in re.findall(r"`(\w+)`", objects)
                  if re.fullmatch(r"[A-Z][a-z]\w*", name)]   # type names, not `H` or `values`
    return found


def _frozen(cls: type) -> bool:
    if dataclasses.is_dataclass(cls):
        return cls.__dataclass_params__.frozen    # type: ignore[attr-defined]
    struct = getattr(cls, "__struct_config__", None)  # msgspec
    if struct is not None:
        return bool(struct.frozen)
    return issubclass(cls, tuple)                   # a NamedTuple


@pytest.mark.parametrize("arrow, name, package", _arrows(), ids=lambda v: str(v))
def test_what_crosses_each_arrow_is_a_typed_frozen_object(arrow, name, package):
    module = importlib.import_module(package)
    cls = getattr(module, name, None)
    assert isinstance(cls, type), f"{arrow}: {package} defines no type {name}"
    if package.count(".") == 1:       # a stage package: the type is part of its public API
        assert name in getattr(module, "__all__", ()), f"{name} is not in {package}.__all__"
    assert _frozen(cls), f"{arrow}: {package}.{name} is not frozen"

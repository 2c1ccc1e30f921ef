"""The documentation of a config dataclass's options, read from its own source.

Every option of a config dataclass is documented by the string literal right after it (an
attribute docstring)::

    patch_size: float = 0.01
    \"\"\"[m] Largest quadrature element for rectangles and heightfields.\"\"\"

A physical unit, when the option has one, opens the docstring in square brackets
(``[m]``, ``[1/m]``, ``[s]``, ``[MiB]``, ``[deg]``) and is not repeated in the text.
:func:`option_docs` reads these docstrings with :mod:`ast` from the class's source (the
class itself, then its bases), and the types and defaults from the dataclass, so the
help that ``python -m nlosfw plugins NAME`` prints cannot drift from the code.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import inspect
import re
import textwrap
import types
from dataclasses import dataclass
from typing import Any, Union, get_args, get_origin, get_type_hints

#: The unit tag that may open an option's docstring: ``[m] ...``.
UNIT_TAG = re.compile(r"^\[(?P<unit>[^\]\s][^\]]*)\]\s*")

_SENTENCE_END = re.compile(r"(?<=[.!?])\s+(?=[A-Z])")


@dataclass(frozen=True)
class OptionDoc:
    """One option of a config dataclass, as the command line shows it."""

    name: str
    type: str
    """Readable type: ``float``, ``int or null``, ``list of float``, ``a | b | c``."""
    default: Any
    """The default as a plain (YAML-safe) value."""
    unit: str
    """The unit from the docstring's ``[unit]`` tag ('' when it has none)."""
    doc: str
    """The docstring without its unit tag, on one line ('' when undocumented)."""

    @property
    def summary(self) -> str:
        """The first sentence of :attr:`doc`."""
        return first_sentence(self.doc)


def first_sentence(text: str) -> str:
    """The first sentence of ``text`` (up to a full stop followed by a capital letter)."""
    return _SENTENCE_END.split(" ".join(text.split()), maxsplit=1)[0]


def option_docs(cls: type, groups: bool = False) -> tuple[OptionDoc, ...]:
    """The options of config dataclass ``cls`` in field order, with type, default, unit, doc.

    With ``groups`` an option that is a group of options (a nested config dataclass) is
    given as its options, named ``group.option`` (as the command line writes them), their
    defaults the group's default's (a config may give a group defaults of its own)."""
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"expected a dataclass type, got {cls!r}")
    return _option_docs(cls, groups, None)


def _option_docs(cls: type, groups: bool, defaults: object | None
                 ) -> tuple[OptionDoc, ...]:
    """:func:`option_docs`, the defaults read from ``defaults`` (an instance) if given."""
    hints = get_type_hints(cls)
    docs = attribute_docstrings(cls)
    out: list[OptionDoc] = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp = hints.get(f.name, Any)
        default = _default(f) if defaults is None else getattr(defaults, f.name)
        if groups and isinstance(tp, type) and dataclasses.is_dataclass(tp):
            given = default if isinstance(default, tp) else None    # not "???" or None
            out += [dataclasses.replace(o, name=f"{f.name}.{o.name}")
                    for o in _option_docs(tp, groups, given)]
            continue
        unit, doc = split_unit(docs.get(f.name, ""))
        out.append(OptionDoc(name=f.name, type=type_text(tp),
                             default=_plain(default), unit=unit, doc=doc))
    return tuple(out)


def attribute_docstrings(cls: type) -> dict[str, str]:
    """Field name -> the string literal that follows it in the class body (bases first, so a
    subclass's docstring of the same field wins); classes without source give none."""
    found: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if klass is object:
            continue
        try:
            source = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        tree = ast.parse(source)
        node = next((n for n in tree.body if isinstance(n, ast.ClassDef)), None)
        if node is None:
            continue
        for stmt, after in zip(node.body, node.body[1:], strict=False):
            if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
                    and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                    and isinstance(after.value.value, str)):
                found[stmt.target.id] = inspect.cleandoc(after.value.value)
    return found


def split_unit(docstring: str) -> tuple[str, str]:
    """(unit, text) of an option docstring: the ``[unit]`` tag and the rest on one line."""
    text = " ".join(docstring.split())
    match = UNIT_TAG.match(text)
    if match is None:
        return "", text
    return match.group("unit").strip(), text[match.end():]


def type_text(tp: Any) -> str:
    """A short readable name of an option's type."""
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        text = " or ".join(type_text(a) for a in rest)
        return f"{text} or null" if len(rest) < len(args) else text
    if origin in (tuple, list):
        if origin is list or (len(args) == 2 and args[1] is Ellipsis):
            return f"list of {type_text(args[0])}" if args else "list"
        return "[" + ", ".join(type_text(a) for a in args) + "]"
    if origin is dict or tp is dict:
        return "mapping"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return " | ".join(str(m.value) for m in tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return "group"
    if tp is Any:
        return "any"
    return getattr(tp, "__name__", str(tp))


def _default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def _plain(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    return value

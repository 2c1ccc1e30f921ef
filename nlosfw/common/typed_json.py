"""Frozen dataclasses as JSON documents: encode, decode with validation, JSON Schema.

A document type is a tree of dataclasses whose fields are annotated with ``bool``,
``int``, ``float``, ``str``, ``Literal[...]``, an ``Enum``, ``X | None``,
``list[X]``, ``tuple[X, ...]``, ``tuple[X, Y]``, ``dict[str, X]``, another dataclass
or ``Any`` (free-form JSON). From that one definition come:

* :func:`to_json`: the plain JSON value (dataclass fields in declaration order; a
  non-finite float becomes ``null`` where the type admits ``None``);
* :func:`from_json`: the dataclass back, checking every key and type; a mistake
  raises :class:`~nlosfw.common.errors.DataError` naming the key path;
* :func:`json_schema`: the JSON Schema (draft 2020-12) of the document;
* :func:`outline`: a compact text outline of the document for the docs.

A field made with :func:`optional` may be absent: it defaults to ``None`` and is left
out of the JSON when it is ``None`` (``null`` is then not a valid value for it).
Otherwise every field is required, and ``X | None`` means the value may be ``null``.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import numbers
import types
from collections.abc import Mapping
from functools import cache
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from nlosfw.common.errors import DataError

T = TypeVar("T")

_NONE = type(None)
_OPTIONAL = "typed_json.optional"
_DOC = "typed_json.doc"
_KEY = "typed_json.key"
JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def optional(doc: str = "", key: str = "") -> Any:
    """A dataclass field that may be absent from the document (``None`` when it is); ``key``
    names the keys of a ``dict`` in :func:`outline`."""
    return dataclasses.field(default=None, metadata={_OPTIONAL: True, _DOC: doc, _KEY: key})


def documented(doc: str, key: str = "", **field_options: Any) -> Any:
    """A dataclass field with a description (and, for a ``dict``, the name of its keys)."""
    return dataclasses.field(metadata={_DOC: doc, _KEY: key}, **field_options)


# ------------------------------------------------------------------ encode
def to_json(document: Any) -> Any:
    """The plain JSON value of a dataclass document (validated against its types)."""
    return _encode(document, type(document), "")


def _encode(value: Any, tp: Any, where: str) -> Any:
    if tp is Any:
        return _plain(value, where)
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None or (_NONE in args and _is_non_finite(value)):
            if _NONE not in args:
                raise _bug(where, "is None but its type does not admit null")
            return None
        (inner,) = [a for a in args if a is not _NONE]
        return _encode(value, inner, where)
    if _is_dataclass(tp):
        if not isinstance(value, tp):
            raise _bug(where, f"expected {tp.__name__}, got {type(value).__name__}")
        out = {}
        for f, ftype in _fields(tp):
            item = getattr(value, f.name)
            if item is None and f.metadata.get(_OPTIONAL):
                continue
            out[f.name] = _encode(item, ftype, _join(where, f.name))
        return out
    if origin is dict:
        return {str(k): _encode(v, args[1], _join(where, str(k))) for k, v in value.items()}
    if origin in (list, tuple):
        items = list(value)
        return [_encode(v, _item_type(tp, i), f"{where}[{i}]") for i, v in enumerate(items)]
    return _encode_scalar(value, tp, where)


def _encode_scalar(value: Any, tp: Any, where: str) -> Any:
    if get_origin(tp) is Literal:
        if value not in get_args(tp):
            raise _bug(where, f"{value!r} is not one of {get_args(tp)}")
        return value
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return tp(value).value
    if tp is bool and isinstance(value, (bool, _numpy_bool())):
        return bool(value)
    if tp is int and isinstance(value, numbers.Integral) and not isinstance(value, bool):
        return int(value)
    if tp is float and isinstance(value, numbers.Real) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise _bug(where, f"is {value}, which JSON cannot hold (declare it float | None)")
        return float(value)
    if tp is str and isinstance(value, str):
        return value
    raise _bug(where, f"expected {_type_word(tp)}, got {value!r} ({type(value).__name__})")


def _plain(value: Any, where: str) -> Any:
    """Free-form data as JSON: numpy scalars become numbers, non-finite floats null."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v, _join(where, str(k))) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise _bug(where, f"{type(value).__name__} is not JSON data")


def _is_non_finite(value: Any) -> bool:
    return (isinstance(value, numbers.Real) and not isinstance(value, bool)
            and not math.isfinite(value))


def _numpy_bool() -> type:
    try:
        import numpy as np
    except ImportError:  # pragma: no cover - numpy is a dependency
        return bool
    return np.bool_


def _bug(where: str, problem: str) -> TypeError:
    return TypeError(f"{where or 'document'}: {problem}")


# ------------------------------------------------------------------ decode
def from_json(cls: type[T], data: Any, where: str = "") -> T:
    """The dataclass ``cls`` from its JSON value, checking every key and type.

    Raises :class:`DataError` ``"<where>: <key path>: <problem>"`` on one line (``where``
    names the document, e.g. its file). Like JSON Schema, an integer may be written
    ``3.0``.
    """
    try:
        return _decode(data, cls, "")
    except DataError as err:
        raise DataError(f"{where}: {err}" if where else str(err)) from None


def _decode(value: Any, tp: Any, where: str) -> Any:
    if tp is Any:
        return value
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None:
            if _NONE in args:
                return None
            raise _invalid(where, f"must be {_type_word(tp)}, got null")
        (inner,) = [a for a in args if a is not _NONE]
        if _is_dataclass(inner) or get_origin(inner) in (dict, list, tuple):
            return _decode(value, inner, where)
        return _decode_scalar(value, inner, where, expected=_type_word(tp))
    if _is_dataclass(tp):
        return _decode_dataclass(value, tp, where)
    if origin is dict:
        if not isinstance(value, dict):
            raise _invalid(where, f"must be an object, got {_describe(value)}")
        return {k: _decode(v, args[1], _join(where, k)) for k, v in value.items()}
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise _invalid(where, f"must be {_type_word(tp)}, got {_describe(value)}")
        fixed = origin is tuple and args[-1] is not Ellipsis
        if fixed and len(value) != len(args):
            raise _invalid(where, f"must be {_type_word(tp)}, got {len(value)} values")
        items = [_decode(v, _item_type(tp, i), f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    return _decode_scalar(value, tp, where)


def _decode_dataclass(value: Any, cls: Any, where: str) -> Any:
    if not isinstance(value, dict):
        raise _invalid(where, f"must be an object, got {_describe(value)}")
    fields = _fields(cls)
    names = [f.name for f, _ in fields]
    unknown = sorted(set(value) - set(names))
    if unknown:
        raise _invalid(_join(where, unknown[0]), f"unknown key; valid keys: {', '.join(names)}")
    kwargs = {}
    for f, ftype in fields:
        if f.name in value:
            optional_key = f.metadata.get(_OPTIONAL)  # absent rather than null
            kwargs[f.name] = _decode(value[f.name], _without_none(ftype) if optional_key
                                     else ftype, _join(where, f.name))
        elif not f.metadata.get(_OPTIONAL):
            raise _invalid(_join(where, f.name), "is missing")
    return cls(**kwargs)


def _decode_scalar(value: Any, tp: Any, where: str, expected: str = "") -> Any:
    expected = expected or _type_word(tp)
    if get_origin(tp) is Literal:
        for choice in get_args(tp):
            if value == choice and isinstance(value, bool) == isinstance(choice, bool):
                return choice
        raise _invalid(where, f"must be {expected}, got {_describe(value)}")
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            raise _invalid(where, f"must be {expected}, got {_describe(value)}") from None
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    ok = {
        bool: isinstance(value, bool),
        int: number and (isinstance(value, int) or value.is_integer()),
        float: number,
        str: isinstance(value, str),
    }.get(tp)
    if ok is None:
        raise TypeError(f"{where}: unsupported type {tp!r} in a JSON document")
    if not ok:
        raise _invalid(where, f"must be {expected}, got {_describe(value)}")
    return tp(value) if tp in (int, float) else value


def _invalid(where: str, problem: str) -> DataError:
    return DataError(f"{where}: {problem}" if where else problem)


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    text = repr(value)
    return f"{text[:37]}..." if len(text) > 40 else text


# ------------------------------------------------------------------ schema
def json_schema(cls: type, title: str = "", schema_id: str = "") -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of documents of the dataclass ``cls``.

    The root is ``cls`` itself; nested dataclasses are ``$defs`` referenced by name,
    every object is closed (``additionalProperties: false``).
    """
    builder = _SchemaBuilder()
    root = builder.dataclass_schema(cls)
    head: dict[str, Any] = {"$schema": JSON_SCHEMA_DIALECT}
    if schema_id:
        head["$id"] = schema_id
    if title:
        head["title"] = title
    defs = {name: schema for name, schema in builder.defs.items() if name != cls.__name__}
    return {**head, **root, "$defs": dict(sorted(defs.items()))}


class _SchemaBuilder:
    """Builds the schemas of one document, collecting its nested dataclasses in ``defs``."""

    def __init__(self) -> None:
        self.defs: dict[str, Any] = {}

    def schema(self, tp: Any) -> dict[str, Any]:
        if tp is Any:
            return {}
        origin, args = get_origin(tp), get_args(tp)
        if origin in (Union, types.UnionType):
            (inner,) = [a for a in args if a is not _NONE]
            schema = self.schema(inner)
            if set(schema) == {"type"} and isinstance(schema["type"], str):
                return {"type": [schema["type"], "null"]}
            return {"anyOf": [schema, {"type": "null"}]}
        if _is_dataclass(tp):
            name = tp.__name__
            if name not in self.defs:
                self.defs[name] = {}  # placeholder: recursion and repeated use
                self.defs[name] = self.dataclass_schema(tp)
            return {"$ref": f"#/$defs/{name}"}
        if origin is dict:
            return {"type": "object", "additionalProperties": self.schema(args[1])}
        if origin in (list, tuple):
            if origin is tuple and args[-1] is not Ellipsis:
                return {"type": "array", "prefixItems": [self.schema(a) for a in args],
                        "minItems": len(args), "maxItems": len(args)}
            return {"type": "array", "items": self.schema(args[0])}
        return _scalar_schema(tp)

    def dataclass_schema(self, cls: Any) -> dict[str, Any]:
        properties, required = {}, []
        for f, ftype in _fields(cls):
            inner = ftype
            if f.metadata.get(_OPTIONAL):  # absent rather than null
                inner = _without_none(ftype)
            else:
                required.append(f.name)
            schema = self.schema(inner)
            if f.metadata.get(_DOC):
                schema = {"description": f.metadata[_DOC], **schema}
            properties[f.name] = schema
        out: dict[str, Any] = {"type": "object"}
        doc = _summary(cls)
        if doc:
            out["description"] = doc
        return {**out, "properties": properties, "required": required,
                "additionalProperties": False}


def _scalar_schema(tp: Any) -> dict[str, Any]:
    args = get_args(tp)
    if get_origin(tp) is Literal:
        return {"const": args[0]} if len(args) == 1 else {"enum": list(args)}
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return {"enum": [m.value for m in tp]}
    words = {bool: "boolean", int: "integer", float: "number", str: "string"}
    if tp not in words:
        raise TypeError(f"unsupported type {tp!r} in a JSON document")
    return {"type": words[tp]}


def _summary(cls: Any) -> str:
    """The first paragraph of a class's own docstring, on one line."""
    doc = cls.__dict__.get("__doc__") or ""
    if doc.startswith(f"{cls.__name__}("):  # dataclass's generated signature
        return ""
    return " ".join(doc.strip().split("\n\n")[0].split())


# ------------------------------------------------------------------ outline
def outline(cls: type, width: int = 90) -> str:
    """A compact outline of ``cls``'s documents: ``key?`` may be absent, ``a | b`` are the
    allowed values, ``{...}`` an object, ``<name>`` a key chosen by the data."""
    return "\n".join(_block(cls, "", width)) + "\n"


def _block(cls: Any, indent: str, width: int) -> list[str]:
    lines: list[str] = []
    plain: list[str] = []

    def flush() -> None:
        if plain:
            lines.extend(_wrap(plain, indent, width))
            plain.clear()

    for labels, tp, key in _groups(cls):
        label = " | ".join(labels)
        if not _is_structured(tp):
            plain.append(label + _suffix(tp))
            if not indent:  # the top level: one key a line
                flush()
            continue
        flush()
        inline = f"{indent}{label}: {_inline(tp, key)}"
        if len(inline) <= width:
            lines.append(inline)
        else:
            lines.append(f"{indent}{label}:")
            lines.extend(_nested(tp, key, indent + "  ", width))
    flush()
    return lines


def _groups(cls: Any) -> list[tuple[list[str], Any, str | None]]:
    """``cls``'s fields as (labels, type, key name), consecutive fields of one dataclass
    type merged (``a | b: {...}``)."""
    groups: list[tuple[list[str], Any, str | None]] = []
    for f, ftype in _fields(cls):
        label = f.name + ("?" if f.metadata.get(_OPTIONAL) else "")
        tp, key = _without_none(ftype), f.metadata.get(_KEY) or None
        if groups and _is_dataclass(tp) and groups[-1][1] is tp:
            groups[-1][0].append(label)
        else:
            groups.append(([label], tp, key))
    return groups


def _nested(tp: Any, key: str | None, indent: str, width: int) -> list[str]:
    """Block lines of a structured value that does not fit on one line."""
    if _is_dataclass(tp):
        return _block(tp, indent, width)
    value = _without_none(get_args(tp)[1])
    line = f"{indent}<{key or 'key'}>: {_inline(value, None)}"
    if len(line) <= width or not _is_dataclass(value):
        return [line]
    return [f"{indent}<{key or 'key'}>:", *_block(value, indent + "  ", width)]


def _inline(tp: Any, key: str | None) -> str:
    if _is_dataclass(tp):
        parts = []
        for f, ftype in _fields(tp):
            label = f.name + ("?" if f.metadata.get(_OPTIONAL) else "")
            inner = _without_none(ftype)
            if _is_structured(inner):
                parts.append(f"{label}: {_inline(inner, f.metadata.get(_KEY))}")
            else:
                parts.append(label + _suffix(inner))
        return "{" + ", ".join(parts) + "}"
    if get_origin(tp) is dict:
        value = _inline(_without_none(get_args(tp)[1]), None)
        return f"{{<{key or 'key'}>: {value}}}" if value else "{...}"
    return _suffix(tp).removeprefix(": ")


def _suffix(tp: Any) -> str:
    """``: a | b`` for choices, ``: [n numbers]`` for arrays, nothing for plain scalars."""
    origin, args = get_origin(tp), get_args(tp)
    if origin is Literal:
        return ": " + " | ".join(str(a) for a in args)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return ": " + " | ".join(str(m.value) for m in tp)
    if origin in (list, tuple):
        if origin is tuple and args[-1] is not Ellipsis:
            return f": [{len(args)} {_plural(args[0])}]"
        return f": [{_plural(_without_none(args[0]))}]"
    return ""


def _plural(tp: Any) -> str:
    return {bool: "booleans", int: "integers", float: "numbers", str: "strings"}.get(tp, "values")


def _is_structured(tp: Any) -> bool:
    return _is_dataclass(tp) or get_origin(tp) is dict


def _wrap(labels: list[str], indent: str, width: int) -> list[str]:
    lines, current = [], ""
    for i, label in enumerate(labels):
        piece = label + ("," if i < len(labels) - 1 else "")
        candidate = f"{current} {piece}" if current else f"{indent}{piece}"
        if current and len(candidate) > width:
            lines.append(current)
            candidate = f"{indent}{piece}"
        current = candidate
    return [*lines, current] if current else lines


# ------------------------------------------------------------------ shared helpers
@cache
def _fields(cls: Any) -> tuple[tuple[dataclasses.Field, Any], ...]:
    hints = get_type_hints(cls)
    return tuple((f, hints[f.name]) for f in dataclasses.fields(cls))


def _is_dataclass(tp: Any) -> bool:
    """Whether ``tp`` is a dataclass type (not an instance)."""
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _without_none(tp: Any) -> Any:
    if get_origin(tp) in (Union, types.UnionType):
        rest = [a for a in get_args(tp) if a is not _NONE]
        if len(rest) == 1:
            return rest[0]
    return tp


def _item_type(tp: Any, index: int) -> Any:
    args = get_args(tp)
    if not args:
        return Any
    if get_origin(tp) is tuple and args[-1] is not Ellipsis:
        return args[index] if index < len(args) else Any
    return args[0]


def _type_word(tp: Any) -> str:
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        return " or ".join(_type_word(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (list, tuple):
        if origin is tuple and args and args[-1] is not Ellipsis:
            return f"an array of {len(args)} values"
        return "an array"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return "one of " + ", ".join(repr(m.value) for m in tp)
    if _is_dataclass(tp) or origin is dict:
        return "an object"
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string",
            _NONE: "null"}.get(tp, str(tp))


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name

"""Typed JSON documents on msgspec: encode, decode with one-line errors, JSON Schema, outline.

A document type is a :class:`Document` (a frozen msgspec Struct) whose fields are annotated
with ``bool``, ``int``, ``float``, ``str``, ``Literal[...]``, an ``Enum``, ``X | None``,
``tuple[X, ...]``, ``tuple[X, Y]``, ``dict[str, X]``, another Document or ``object``
(free-form JSON); ``Annotated[X, doc("...")]`` describes a field. msgspec encodes and
decodes them; this module adds:

* :func:`encode` / :func:`to_json`: the JSON, checked against the types (a value the type
  does not admit, such as NaN for a ``float``, raises ``TypeError``; numpy scalars are
  numbers, a non-finite float becomes ``null`` where the type admits ``None``);
* :func:`from_json`: the document from its JSON value; a mistake raises
  :class:`~nlosfw.common.errors.DataError` naming the key path and what is valid;
* :func:`json_schema`: the JSON Schema (draft 2020-12) of the document;
* :func:`outline`: a compact text outline of the document for the docs.

A field ``name: Absent[X] = None`` may be absent: it is left out of the JSON when it is
``None`` and ``null`` is not a valid value for it. Every other field is required in the
JSON (a default other than ``None`` is a convenience for Python callers, given as a
``default_factory`` so that it is always written), and ``X | None`` means it may be ``null``.
"""

from __future__ import annotations

import re
import typing
from typing import TYPE_CHECKING, NamedTuple, TypeAlias, TypeVar

import msgspec
from msgspec import inspect as mi

from nlosfw.common.errors import DataError

T = TypeVar("T")
D = TypeVar("D", bound="Document")
JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"

if TYPE_CHECKING:
    Absent: TypeAlias = T | None
else:
    class Absent:
        """``Absent[X]``: a field that may be absent; ``X`` to msgspec (so ``null`` is
        refused), ``X | None`` to the type checker (absent is ``None``)."""

        def __class_getitem__(cls, tp: object) -> object:
            return tp


class Document(msgspec.Struct, frozen=True, kw_only=True, omit_defaults=True,
               forbid_unknown_fields=True):
    """Base of the typed JSON documents: a frozen Struct that leaves absent fields out.
    Declare each document ``class X(Document, frozen=True, kw_only=True)`` (msgspec does
    not inherit ``kw_only``, and the type checker reads ``frozen`` from the class line)."""


def doc(text: str, key: str = "") -> msgspec.Meta:
    """A field's description (``Annotated[X, doc(...)]``); ``key`` names a dict's keys in
    :func:`outline`."""
    return msgspec.Meta(description=text, extra={"key": key} if key else None)


# ------------------------------------------------------------------ encode
def encode(document: Document) -> bytes:
    """The compact JSON of ``document``, checked against its types."""
    raw = msgspec.json.encode(document, enc_hook=_plain)
    try:   # decoding checks the types, and turns an int given for a float into a float
        checked = msgspec.json.decode(raw, type=type(document))
    except msgspec.ValidationError as err:
        raise TypeError(f"{type(document).__name__}: {err}") from None
    return msgspec.json.encode(checked)


def to_json(document: Document) -> dict[str, object]:
    """The plain JSON object of ``document`` (checked as :func:`encode` does)."""
    data: dict[str, object] = msgspec.json.decode(encode(document))
    return data


def _plain(value: object) -> object:
    """numpy scalars (and arrays) as Python numbers (and lists)."""
    tolist = getattr(value, "tolist", None)
    if tolist is None:
        raise NotImplementedError(f"{type(value).__name__} is not JSON data")
    result: object = tolist()
    return result


# ------------------------------------------------------------------ decode
def from_json(cls: type[D], data: object, where: str = "") -> D:
    """The document ``cls`` from its JSON value, checking every key and type.

    Raises :class:`DataError` ``"<where>: <key path>: <problem>"`` on one line (``where``
    names the document, e.g. its file).
    """
    try:
        if isinstance(data, dict):
            for f in msgspec.structs.fields(cls):
                if f.default is not None and not f.required and f.encode_name not in data:
                    raise DataError(f"{f.encode_name}: is missing")   # a Python-side default
        return msgspec.convert(data, cls)
    except msgspec.ValidationError as err:
        problem = _explain(str(err), data, cls)
    except DataError as err:
        problem = str(err)
    raise DataError(f"{where}: {problem}" if where else problem)


def _explain(message: str, data: object, cls: type) -> str:
    """msgspec's error in words: the key path in full (dict keys too) and what is valid."""
    text, _, at = message.partition(" - at `$")
    node: mi.Type = mi.type_info(cls)
    value, where = data, ""
    for name, index in re.findall(r"\.([^.\[`]+)|\[(\d+|\.\.\.)\]", at):
        node = _bare(node)
        if name and isinstance(node, mi.StructType):
            node = next(_declared(node.cls, f) for f in node.fields if f.encode_name == name)
            value, where = value[name], _join(where, name)  # type: ignore[index]
        elif index == "..." and isinstance(node, mi.DictType) and isinstance(value, dict):
            key = next((k for k, v in value.items() if _fails(v, node.value_type)), "")
            node, value, where = node.value_type, value.get(key), _join(where, key)
        elif index.isdigit() and isinstance(value, list):
            items = getattr(node, "item_types", None)
            node = items[int(index)] if items else getattr(node, "item_type", node)
            value, where = value[int(index)], f"{where}[{index}]"
    node = _bare(node, keep_none=True)
    field = re.fullmatch(r"Object (missing required|contains unknown) field `(.+)`", text)
    if field and field.group(1) == "missing required":
        return f"{_join(where, field.group(2))}: is missing"
    if field and isinstance(node, mi.StructType):
        valid = ", ".join(f.encode_name for f in node.fields)
        return f"{_join(where, field.group(2))}: unknown key; valid keys: {valid}"
    got = _describe(value)
    if isinstance(node, mi.TupleType) and isinstance(value, list):
        got = f"{len(value)} values"
    problem = f"must be {_words(node)}, got {got}"
    return f"{where}: {problem}" if where else problem


def _fails(value: object, node: mi.Type) -> bool:
    """Whether ``value`` is not a valid ``node`` (for a document; other values: True)."""
    if not isinstance(node, mi.StructType):
        return True
    try:
        msgspec.convert(value, node.cls)
    except msgspec.ValidationError:
        return True
    return False


def _words(node: mi.Type) -> str:
    if isinstance(node, mi.UnionType):
        return " or ".join(_words(t) for t in node.types)
    if isinstance(node, mi.LiteralType):
        return "one of " + ", ".join(repr(v) for v in node.values)
    if isinstance(node, mi.EnumType):
        return "one of " + ", ".join(repr(m.value) for m in node.cls)
    if isinstance(node, mi.TupleType):
        return f"an array of {len(node.item_types)} values"
    words = {mi.BoolType: "true or false", mi.IntType: "an integer", mi.FloatType: "a number",
             mi.StrType: "a string", mi.NoneType: "null", mi.StructType: "an object",
             mi.DictType: "an object", mi.ListType: "an array", mi.VarTupleType: "an array"}
    return words.get(type(node), "valid JSON")


def _describe(value: object) -> str:
    if value is None:
        return "null"
    text = repr(value)
    return f"{text[:37]}..." if len(text) > 40 else text


# ------------------------------------------------------------------ schema
def json_schema(cls: type[Document], title: str = "",
                schema_id: str = "") -> dict[str, object]:
    """The JSON Schema (draft 2020-12) of documents of ``cls``.

    The root is ``cls`` itself; nested documents are ``$defs`` referenced by name, every
    object is closed (``additionalProperties: false``).
    """
    defs: dict[str, dict[str, object]] = {}
    root = _struct_schema(_struct(mi.type_info(cls)), defs)
    head: dict[str, object] = {"$schema": JSON_SCHEMA_DIALECT}
    if schema_id:
        head["$id"] = schema_id
    if title:
        head["title"] = title
    defs.pop(cls.__name__, None)
    return {**head, **root, "$defs": dict(sorted(defs.items()))}


def _schema(node: mi.Type, defs: dict[str, dict[str, object]]) -> dict[str, object]:
    if isinstance(node, mi.UnionType):
        schema = _schema(_bare(node), defs)
        if set(schema) == {"type"} and isinstance(schema["type"], str):
            return {"type": [schema["type"], "null"]}
        return {"anyOf": [schema, {"type": "null"}]}
    if isinstance(node, mi.StructType):
        name = node.cls.__name__
        if name not in defs:
            defs[name] = {}    # a placeholder while it is built (repeated use)
            defs[name] = _struct_schema(node, defs)
        return {"$ref": f"#/$defs/{name}"}
    if isinstance(node, mi.DictType):
        return {"type": "object", "additionalProperties": _schema(node.value_type, defs)}
    if isinstance(node, mi.TupleType):
        n = len(node.item_types)
        return {"type": "array", "prefixItems": [_schema(t, defs) for t in node.item_types],
                "minItems": n, "maxItems": n}
    if isinstance(node, (mi.ListType, mi.VarTupleType)):
        return {"type": "array", "items": _schema(node.item_type, defs)}
    if isinstance(node, mi.LiteralType):
        values = list(node.values)
        return {"const": values[0]} if len(values) == 1 else {"enum": values}
    if isinstance(node, mi.EnumType):
        return {"enum": [m.value for m in node.cls]}
    if isinstance(node, mi.AnyType):
        return {}
    words = {mi.BoolType: "boolean", mi.IntType: "integer", mi.FloatType: "number",
             mi.StrType: "string"}
    if type(node) not in words:
        raise TypeError(f"unsupported type {node!r} in a JSON document")
    return {"type": words[type(node)]}


def _struct_schema(node: mi.StructType, defs: dict[str, dict[str, object]]) -> dict[str, object]:
    properties = {}
    for f in _fields(node):
        schema = _schema(f.node, defs)
        properties[f.name] = {"description": f.doc, **schema} if f.doc else schema
    out: dict[str, object] = {"type": "object"}
    summary = " ".join((node.cls.__dict__.get("__doc__") or "").strip().split("\n\n")[0].split())
    if summary:
        out["description"] = summary
    return {**out, "properties": properties,
            "required": [f.name for f in _fields(node) if not f.optional],
            "additionalProperties": False}


# ------------------------------------------------------------------ outline
def outline(cls: type[Document], width: int = 90) -> str:
    """A compact outline of ``cls``'s documents: ``key?`` may be absent, ``a | b`` are the
    allowed values, ``{...}`` an object, ``<name>`` a key chosen by the data."""
    return "\n".join(_block(_struct(mi.type_info(cls)), "", width)) + "\n"


def _block(node: mi.StructType, indent: str, width: int) -> list[str]:
    lines: list[str] = []
    plain: list[str] = []

    def flush() -> None:
        if plain:
            lines.extend(_wrap(plain, indent, width))
            plain.clear()

    for labels, tp, key in _groups(node):
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


def _groups(node: mi.StructType) -> list[tuple[list[str], mi.Type, str]]:
    """The fields as (labels, type, key name), consecutive fields of one document type
    merged (``a | b: {...}``)."""
    groups: list[tuple[list[str], mi.Type, str]] = []
    for f in _fields(node):
        label, tp = f.name + ("?" if f.optional else ""), _bare(f.node)
        last = groups[-1][1] if groups else None
        if (isinstance(tp, mi.StructType) and isinstance(last, mi.StructType)
                and last.cls is tp.cls):
            groups[-1][0].append(label)
        else:
            groups.append(([label], tp, f.key))
    return groups


def _nested(tp: mi.Type, key: str, indent: str, width: int) -> list[str]:
    """Block lines of a structured value that does not fit on one line."""
    if isinstance(tp, mi.StructType):
        return _block(tp, indent, width)
    value = _bare(getattr(tp, "value_type", tp))
    line = f"{indent}<{key or 'key'}>: {_inline(value, '')}"
    if len(line) <= width or not isinstance(value, mi.StructType):
        return [line]
    return [f"{indent}<{key or 'key'}>:", *_block(value, indent + "  ", width)]


def _inline(tp: mi.Type, key: str) -> str:
    if isinstance(tp, mi.StructType):
        parts = []
        for f in _fields(tp):
            label, inner = f.name + ("?" if f.optional else ""), _bare(f.node)
            parts.append(f"{label}: {_inline(inner, f.key)}" if _is_structured(inner)
                         else label + _suffix(inner))
        return "{" + ", ".join(parts) + "}"
    if isinstance(tp, mi.DictType):
        value = _inline(_bare(tp.value_type), "")
        return f"{{<{key or 'key'}>: {value}}}" if value else "{...}"
    return _suffix(tp).removeprefix(": ")


def _suffix(tp: mi.Type) -> str:
    """``: a | b`` for choices, ``: [n numbers]`` for arrays, nothing for plain scalars."""
    if isinstance(tp, mi.LiteralType):
        return ": " + " | ".join(str(a) for a in tp.values)
    if isinstance(tp, mi.EnumType):
        return ": " + " | ".join(str(m.value) for m in tp.cls)
    if isinstance(tp, mi.TupleType):
        return f": [{len(tp.item_types)} {_plural(tp.item_types[0])}]"
    if isinstance(tp, (mi.ListType, mi.VarTupleType)):
        return f": [{_plural(_bare(tp.item_type))}]"
    return ""


def _plural(tp: mi.Type) -> str:
    words = {mi.BoolType: "booleans", mi.IntType: "integers", mi.FloatType: "numbers",
             mi.StrType: "strings"}
    return words.get(type(tp), "values")


def _is_structured(tp: mi.Type) -> bool:
    return isinstance(tp, (mi.StructType, mi.DictType))


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
class _Field(NamedTuple):
    name: str
    node: mi.Type
    optional: bool   # may be absent (default None)
    doc: str
    key: str         # the name of a dict's keys in the outline


def _fields(node: mi.StructType) -> list[_Field]:
    out = []
    for f in node.fields:
        tp, text, key = _declared(node.cls, f), "", ""
        if isinstance(tp, mi.Metadata):
            text = str((tp.extra_json_schema or {}).get("description", ""))
            key = str((tp.extra or {}).get("key", ""))
            tp = tp.type
        out.append(_Field(f.encode_name, tp, f.default is None, text, key))
    return out


def _declared(cls: type, field: mi.Field) -> mi.Type:
    """A field's type, with the values of a ``Literal`` (that msgspec sorts) in the order
    the class declares them."""
    bare = _bare(field.type)
    if not isinstance(bare, mi.LiteralType):
        return field.type
    hint = typing.get_type_hints(cls)[field.name]
    values = next(typing.get_args(a) for a in (hint, *typing.get_args(hint))
                  if typing.get_origin(a) is typing.Literal)
    return _rebuild(field.type, mi.LiteralType(values=values))


def _rebuild(node: mi.Type, literal: mi.LiteralType) -> mi.Type:
    if isinstance(node, mi.Metadata):
        return mi.Metadata(type=_rebuild(node.type, literal),
                           extra_json_schema=node.extra_json_schema, extra=node.extra)
    if isinstance(node, mi.UnionType):
        return mi.UnionType(types=tuple(_rebuild(t, literal) for t in node.types))
    return literal if isinstance(node, mi.LiteralType) else node


def _struct(node: mi.Type) -> mi.StructType:
    if not isinstance(node, mi.StructType):
        raise TypeError(f"{node!r} is not a Document")
    return node


def _bare(node: mi.Type, keep_none: bool = False) -> mi.Type:
    """``node`` without its metadata and, unless ``keep_none``, without ``| None``."""
    if isinstance(node, mi.Metadata):
        return _bare(node.type, keep_none)
    if isinstance(node, mi.UnionType) and not keep_none:
        rest = [t for t in node.types if not isinstance(t, mi.NoneType)]
        if len(rest) == 1:
            return rest[0]
    return node


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


__all__ = ["JSON_SCHEMA_DIALECT", "Absent", "Document", "doc", "encode", "from_json",
           "json_schema", "outline", "to_json"]

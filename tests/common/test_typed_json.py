"""Typed JSON documents (nlosfw.common.typed_json, on msgspec): the encoder, the reader and
the JSON Schema agree on what a valid document is."""

import enum
import math
from typing import Annotated, Literal

import jsonschema
import msgspec
import numpy as np
import pytest

from nlosfw.common.errors import DataError
from nlosfw.common.typed_json import (
    Absent,
    Document,
    doc,
    from_json,
    json_schema,
    outline,
    to_json,
)


class Colour(str, enum.Enum):
    RED = "red"
    BLUE = "blue"


class Part(Document, frozen=True, kw_only=True):
    """A part."""

    count: int
    score: float | None


class Doc(Document, frozen=True, kw_only=True):
    """A document."""

    version: Literal[3, 2] = msgspec.field(default_factory=lambda: 3)
    name: str
    colour: Colour
    size: Annotated[tuple[int, int], doc("rows, columns")]
    weights: tuple[float, ...]
    parts: Annotated[dict[str, Part], doc("by label", key="label")]
    note: Annotated[Absent[str], doc("absent unless noted")] = None
    first: Part
    second: Part


def make(**changes):
    values = dict(name="d", colour=Colour.BLUE, size=(2, 3), weights=(0.5, 1),
                  parts={"a": Part(count=1, score=0.25)}, first=Part(count=2, score=None),
                  second=Part(count=3, score=1.0))
    return Doc(**{**values, **changes})


GOOD = {"version": 3, "name": "d", "colour": "blue", "size": [2, 3], "weights": [0.5, 1.0],
        "parts": {"a": {"count": 1, "score": 0.25}}, "first": {"count": 2, "score": None},
        "second": {"count": 3, "score": 1.0}}


def test_encode_omits_absent_keys_and_nulls_non_finite_numbers_where_allowed():
    assert to_json(make()) == GOOD
    doc = make(note="n", first=Part(count=np.int64(2), score=np.float32(-np.inf)),
               second=Part(count=3, score=math.nan))
    out = to_json(doc)
    assert out["note"] == "n" and type(out["first"]["count"]) is int
    assert out["first"]["score"] is None and out["second"]["score"] is None


@pytest.mark.parametrize("bad", [
    make(size=(2, math.inf)),                       # an int that is not one
    make(weights=(math.nan,)),                      # a float that cannot be null
    make(parts={"a": Part(count="1", score=0.0)}),  # a string for an int
])
def test_encode_refuses_values_its_types_do_not_admit(bad):
    with pytest.raises(TypeError):
        to_json(bad)


def test_decode_round_trips():
    doc = from_json(Doc, GOOD)
    assert doc == make(weights=(0.5, 1.0))
    assert isinstance(doc.colour, Colour) and isinstance(doc.weights[1], float)
    assert type(doc.size[0]) is int and doc.version == 3


BAD = [
    ({"version": 4}, "version: must be one of 3, 2, got 4"),
    ({"version": True}, "version: must be one of 3, 2, got True"),
    ({"colour": "green"}, "colour: must be one of 'red', 'blue', got 'green'"),
    ({"size": [2, 3, 4]}, "size: must be an array of 2 values, got 3 values"),
    ({"size": [2, True]}, "size[1]: must be an integer, got True"),
    ({"size": [2, 3.5]}, "size[1]: must be an integer, got 3.5"),
    ({"weights": "1, 2"}, "weights: must be an array, got '1, 2'"),
    ({"parts": {"a": {"count": 1}}}, "parts.a.score: is missing"),
    ({"parts": {"a": {"count": 1, "score": "x"}}}, "parts.a.score: must be a number or null"),
    ({"parts": {"a": {"count": 1, "score": 0.5}, "b": {"count": "x", "score": 0.5}}},
     "parts.b.count: must be an integer, got 'x'"),       # the key of the entry that is bad
    ({"parts": {"a": {"count": 1, "score": 0.5, "hue": 2}}},
     "parts.a.hue: unknown key; valid keys: count, score"),
    ({"note": None}, "note: must be a string, got null"),
    ({"first": None}, "first: must be an object, got null"),
    ({"extra": 1}, "extra: unknown key; valid keys: version, name, colour, size, weights,"),
]


@pytest.mark.parametrize(("change", "message"), BAD, ids=[m for _, m in BAD])
def test_reader_and_schema_reject_the_same_documents(change, message):
    schema = json_schema(Doc, title="doc")
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    assert validator.is_valid(GOOD)
    bad = {**GOOD, **change}
    assert not validator.is_valid(bad)
    with pytest.raises(DataError) as caught:
        from_json(Doc, bad, where="doc.json")
    assert str(caught.value).startswith(f"doc.json: {message}")


@pytest.mark.parametrize("key", ["name", "version"])   # version has a default in Python
def test_a_missing_required_key_is_rejected_by_both(key):
    bad = {k: v for k, v in GOOD.items() if k != key}
    assert not jsonschema.Draft202012Validator(json_schema(Doc)).is_valid(bad)
    with pytest.raises(DataError, match=rf"^{key}: is missing$"):
        from_json(Doc, bad)


def test_schema_shape():
    schema = json_schema(Doc, title="doc", schema_id="urn:doc:3")
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$id"] == "urn:doc:3" and schema["description"] == "A document."
    assert schema["required"] == ["version", "name", "colour", "size", "weights", "parts",
                                  "first", "second"]
    assert schema["properties"]["note"] == {"description": "absent unless noted",
                                            "type": "string"}
    assert schema["properties"]["version"] == {"enum": [3, 2]}  # as declared
    assert schema["properties"]["size"]["prefixItems"] == [{"type": "integer"}] * 2
    assert schema["$defs"]["Part"]["properties"]["score"] == {"type": ["number", "null"]}
    assert schema["$defs"]["Part"]["additionalProperties"] is False


def test_outline():
    assert outline(Doc) == (
        "version: 3 | 2\n"
        "name\n"
        "colour: red | blue\n"
        "size: [2 integers]\n"
        "weights: [numbers]\n"
        "parts: {<label>: {count, score}}\n"
        "note?\n"
        "first | second: {count, score}\n")


def test_outline_breaks_long_objects_into_blocks():
    class Wide(Document, frozen=True, kw_only=True):
        inner: Part
        others: dict[str, Part] = msgspec.field(default_factory=dict)

    assert outline(Wide, width=12) == (
        "inner:\n"
        "  count,\n"
        "  score\n"
        "others:\n"
        "  <key>:\n"
        "    count,\n"
        "    score\n")

"""Untrusted text (file names, scene names, metadata of capture files) made safe for each
output it reaches: terminals, rich markup, matplotlib titles, HTML links, CSV cells,
Markdown, JSON, and Hydra overrides and OmegaConf values (where it stays literal text,
never an interpolation or override syntax). Pure functions of strings, no third-party
imports (rich and matplotlib are not loaded by ``import nlosfw``); each output calls its
neutraliser on every piece of text that came from input.
"""

from __future__ import annotations

import base64
import datetime
import html
import re
import urllib.parse
from collections.abc import Mapping

#: C0 and C1 control characters and DEL (ESC sequences start with one), not tab/newline.
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")
#: Text rich would read as a markup tag: ``[`` then a letter, ``#``, ``/`` or ``@`` (the
#: pattern rich's own ``escape`` uses), and closing tags such as ``[/]``.
_MARKUP = re.compile(r"(\\*)(\[[a-zA-Z#/@][^\[]*?\]|\[/\])")
#: First characters that make a spreadsheet evaluate a cell (and tab / CR, which some
#: spreadsheets skip before one).
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
#: Markdown that could make a link, code, a table cell's end or a backslash escape.
_MARKDOWN_SPECIAL = re.compile(r"([\\`|\[\]])")
#: The start of an OmegaConf interpolation, with the backslashes before it.
_INTERPOLATION = re.compile(r"(\\*)\$\{")
#: A single quote with the backslashes before it.
_QUOTE = re.compile(r"(\\*)'")


#: The most characters of one piece of untrusted text an output shows (a table cell, a
#: label, a value of a run's record): longer text is cut there, saying how long it was.
MAX_SHOWN = 4096


def shortened(text: str, limit: int = MAX_SHOWN) -> str:
    """``text`` when it has at most ``limit`` characters, else its start followed by how
    many it has, ``limit`` characters in all (so shortening it again changes nothing)."""
    if len(text) <= limit:
        return text
    suffix = f"… ({len(text):,} characters)"
    return text[:max(limit - len(suffix), 0)] + suffix


def shortened_data(value: object, limit: int = MAX_SHOWN) -> object:
    """``value`` (data decoded from JSON or YAML) with every text in it, mapping keys
    included, :func:`shortened` (a new value; ``value`` is not changed)."""
    if isinstance(value, str):
        return shortened(value, limit)
    if isinstance(value, Mapping):
        return {shortened_data(k, limit): shortened_data(v, limit) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [shortened_data(v, limit) for v in value]
    return value


def controls_visible(text: str) -> str:
    """``text`` with control characters other than newline and tab (terminal escape
    sequences among them) shown as ``\\xNN`` instead of acting on the terminal."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


def visible(text: str) -> str:
    """``text`` with control characters (terminal escape sequences among them) shown as
    ``\\xNN`` instead of acting on the terminal; newlines become spaces."""
    return controls_visible(text.replace("\r\n", " ").replace("\n", " "))


def console_text(text: object) -> str:
    """``text`` for the rich console: control characters made visible (newlines and tabs
    kept) and every markup tag escaped, so it prints literally (``[/]`` and ``[red]``
    included)."""
    shown = controls_visible(str(text))
    return _MARKUP.sub(lambda m: f"{m.group(1)}{m.group(1)}\\{m.group(2)}", shown)


def plain_title(text: object) -> str:
    """``text`` for a matplotlib title or label: control characters made visible and
    dollar signs escaped (``\\$``), so matplotlib never parses it as maths."""
    return visible(str(text)).replace("$", r"\$")


def href(name: str) -> str:
    """A relative, URL-quoted link to the file ``name`` relative to the document (``./``
    first unless it starts with ``./`` or ``../``: ``javascript:alert(1)`` becomes a file
    name, never a scheme)."""
    quoted = urllib.parse.quote(name, safe="/")
    return quoted if quoted.startswith(("./", "../")) else "./" + quoted


def html_text(text: object) -> str:
    """``text`` escaped for HTML content and attribute values, on one line, control
    characters made visible, at most :data:`MAX_SHOWN` characters of it."""
    return html.escape(visible(shortened(str(text))), quote=True)


def html_block(text: object) -> str:
    """``text`` escaped for an HTML ``<pre>`` block: its lines kept, control characters
    made visible."""
    return html.escape(controls_visible(str(text)), quote=False)


def csv_cell(value: object) -> object:
    """A CSV cell: a string with its control characters made visible (newlines and tabs
    kept), cut to :data:`MAX_SHOWN` characters, and prefixed with ``'`` when it starts with
    ``= + - @`` (or tab) so that spreadsheets show it as text; numbers, and negative
    numbers written as text (``-13.7``, ``-1e-05``: the reports format their numbers),
    unchanged."""
    if not isinstance(value, str):
        return value
    value = controls_visible(shortened(value))
    if value.startswith(_FORMULA_START) and not _NEGATIVE_NUMBER.fullmatch(value):
        return "'" + value
    return value


#: A negative decimal number as Python formats one (``-13.7``, ``-1e-05``, ``-inf``).
_NEGATIVE_NUMBER = re.compile(r"-(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|inf)")


def markdown(text: object) -> str:
    """``text`` for Markdown: HTML escaped (no raw ``<script>``), on one line, at most
    :data:`MAX_SHOWN` characters of it, with the characters that make links, code or table
    cells (``[ ] ` |`` and backslash) backslash-escaped."""
    escaped = html.escape(visible(shortened(str(text))), quote=False)
    return _MARKDOWN_SPECIAL.sub(r"\\\1", escaped)


def omegaconf_literal(text: str) -> str:
    """``text`` as an OmegaConf string value that resolves to ``text`` itself: each ``${``
    escaped (``\\${``, the backslashes before it doubled), so no part of it is ever an
    interpolation (``${oc.env:NAME}`` would read an environment variable)."""
    return _INTERPOLATION.sub(lambda m: m.group(1) * 2 + "\\${", text)


def override_value(text: str) -> str:
    """``text`` as the value of a Hydra override (``key=VALUE``) that composes to ``text``
    itself, whatever it holds (quotes, backslashes, ``${``, ``=``, ``,``, brackets,
    spaces, newlines): single-quoted, as :func:`omegaconf_literal`, a quote escaped and
    the backslashes before a quote (the closing one included) doubled, the only
    backslashes Hydra's grammar un-escapes in a quoted value."""
    inner = _QUOTE.sub(lambda m: m.group(1) * 2 + "\\'", omegaconf_literal(text))
    trailing = len(inner) - len(inner.rstrip("\\"))
    return "'" + inner + "\\" * trailing + "'"


def json_safe(value: object) -> object:
    """``value`` (YAML data of a capture file) with the types JSON lacks converted: dates
    and times to ISO 8601 text, bytes (``!!binary``) to base64 text, sets to lists (sorted
    by their text), tuples to lists, mapping keys to text; numbers, text, arrays, lists and
    None kept."""
    if isinstance(value, Mapping):
        return {_key(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (set, frozenset)):
        return sorted((json_safe(v) for v in value), key=repr)
    if isinstance(value, (datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, (bytes, bytearray)):
        return base64.b64encode(bytes(value)).decode("ascii")
    return value


def _key(key: object) -> object:
    if key is None or isinstance(key, (str, int, float, bool)):
        return key
    converted = json_safe(key)
    return converted if isinstance(converted, str) else str(converted)

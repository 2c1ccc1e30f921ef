"""Hydra flags nlosfw refuses, recognised in every spelling Hydra's parser accepts.

Hydra reads its flags with :mod:`argparse`, which takes any unambiguous prefix of a long
flag (``--exp`` for ``--experimental-rerun``), with its value after ``=`` or as the next
argument. A refused flag is therefore recognised by its prefixes, not by one spelling.
"""

from __future__ import annotations

from collections.abc import Sequence

from nlosfw.common.errors import ConfigError

#: Hydra flags nlosfw refuses, with why: ``--experimental-rerun`` unpickles a file (code
#: would run).
REFUSED_FLAGS = {
    "--experimental-rerun": "it unpickles a file, which can run any code; run the "
                            "configuration again from its overrides instead",
}
#: The shortest prefix argparse reads as a long flag: ``--`` and one character.
_SHORTEST = 3


def refused_flag(arg: str) -> str | None:
    """The refused flag ``arg`` spells (in full or abbreviated, ``=value`` or not), else
    None."""
    if not arg.startswith("--"):
        return None
    name = arg.split("=", 1)[0]
    if len(name) < _SHORTEST:
        return None
    return next((flag for flag in REFUSED_FLAGS if flag.startswith(name)), None)


def refuse_flags(argv: Sequence[str]) -> None:
    """A one-line :class:`ConfigError` when an argument of ``argv`` is a refused flag."""
    for arg in argv:
        flag = refused_flag(arg)
        if flag is not None:
            raise ConfigError("", f"{flag} is not supported: {REFUSED_FLAGS[flag]}")

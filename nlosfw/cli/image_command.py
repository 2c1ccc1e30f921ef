"""``python -m nlosfw image FILE [OVERRIDE ...]``: reconstruct one capture file.

The shorthand of ``capture.path=FILE model=none output.keep=[reconstructions]``: the run
reads FILE (its format detected from its content), preprocesses it, images its phasor
field and writes the volume (``reconstructions/true.hdf5``), the front view, the depth map
and a strip of depth slices (``figures/``), the capture's time profile and
``report.html`` (with the run's own config.yaml, metrics.json and run.log); no split, no
field model. Without an ``imager`` option the run picks the imager for the capture's
geometry (``reconstruction.pick_imager=true``, :mod:`nlosfw.image.choice`) and its log says
which and why; ``imager=NAME`` (or any ``imager.*`` option) chooses. Every other override
applies as in a normal run (``imager=lct``, ``reconstruction.depth_range=[0.3,0.8]``,
``output.keep=[...]``), and Hydra's flags too (``-m imager=fft,lct`` images the capture
with both).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.text import override_value

USAGE = "python -m nlosfw image FILE [OVERRIDE ...]"

#: The start of an override: a key (``+``/``~`` first), then ``=``.
_OVERRIDE = re.compile(r"[+~]*[\w.@/-]+=")

#: What an image run keeps of the large files: the volume, not the capture's copy.
KEEP = "output.keep=[reconstructions]"
#: What an image run without an ``imager`` option adds: the imager picked for the capture.
PICK = "reconstruction.pick_imager=true"


def image_overrides(argv: Sequence[str]) -> list[str]:
    """The overrides of the run ``image FILE [OVERRIDE ...]`` stands for; a one-line error
    when FILE is missing, not a readable file, or the overrides choose another model or
    capture."""
    args = list(argv)
    # FILE is any path (a folder /data/run=3/ included); a first argument that names no
    # file but reads as an override or a flag is a forgotten FILE
    if not args or args[0].startswith("-") or (
            _OVERRIDE.match(args[0]) and not os.path.lexists(Path(args[0]).expanduser())):
        raise ConfigError("", f"image needs a capture file first: {USAGE}")
    path = Path(args[0]).expanduser()
    if not path.exists():
        raise DataError(f"{path}: no such capture file")
    if not path.is_file():
        raise DataError(f"{path}: not a file (give a capture file: {USAGE})")
    if not os.access(path, os.R_OK):
        raise DataError(f"{path}: cannot be read (permission denied)")
    rest = args[1:]
    for arg in rest:
        key = arg.lstrip("+~").split("=", 1)[0]
        if key in ("model", "capture.path"):
            raise ConfigError(key, f"image sets it (capture.path=FILE model=none); to fit a "
                              f"field model run python -m nlosfw capture.path="
                              f"{override_value(str(path))} model=NAME instead")
    flags, overrides = _hydra_flags(rest)
    keep = [] if any(a.lstrip("+~").startswith("output.keep=") for a in overrides) else [KEEP]
    chosen = any(a.lstrip("+~").split("=", 1)[0].split(".", 1)[0] == "imager"
                 or a.lstrip("+~").startswith("reconstruction.pick_imager=")
                 for a in overrides)
    pick = [] if chosen else [PICK]
    # the name is data: quoted so that neither Hydra's grammar nor an OmegaConf
    # interpolation (${oc.env:NAME}) reads anything in it
    return [*flags, f"capture.path={override_value(str(path.absolute()))}", "model=none",
            *keep, *pick, *overrides]


#: Hydra's flags that take a value (the next argument unless written ``--flag=value``).
_VALUE_FLAGS = frozenset({"-cn", "--config-name", "-cp", "--config-path", "-cd",
                          "--config-dir", "-c", "--cfg", "-p", "--package"})


def _hydra_flags(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """(Hydra's flags with their values, the overrides): Hydra reads its flags before the
    overrides (``image FILE -m imager=fft,lct`` sweeps)."""
    flags: list[str] = []
    overrides: list[str] = []
    taking = False
    for arg in args:
        if taking:
            flags.append(arg)
            taking = False
        elif arg.startswith("-"):
            flags.append(arg)
            taking = arg in _VALUE_FLAGS
        else:
            overrides.append(arg)
    return flags, overrides


def image_command(argv: Sequence[str]) -> int:
    """Run ``image FILE [OVERRIDE ...]``; returns the exit status."""
    from nlosfw.cli.app import main as hydra_main

    return hydra_main(image_overrides(argv))

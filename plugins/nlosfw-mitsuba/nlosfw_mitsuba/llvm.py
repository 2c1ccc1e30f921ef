"""Find an LLVM shared library that Dr.Jit's LLVM backend can use (a light module).

Dr.Jit loads ``libLLVM`` at run time and reads ``DRJIT_LIBLLVM_PATH`` once, when
it is first imported. LLVM 15 (the default on Debian 12) crashes inside Dr.Jit
("Cannot select: fminimum"), so we look for LLVM 16 or newer and set the
variable before mitsuba is imported.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from collections.abc import Iterable, Mapping, MutableMapping
from pathlib import Path

from nlosfw.common import PluginError

ENV_VAR = "DRJIT_LIBLLVM_PATH"
#: Oldest LLVM major version that works with Dr.Jit here (15 crashes).
MIN_VERSION = 16
INSTALL_HINT = ("install it with `apt-get install -y libllvm19` (or `brew install llvm` on "
                "macOS), or set DRJIT_LIBLLVM_PATH to a libLLVM of version 16 or newer")

_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)
_DIR_GLOBS = ("/usr/lib/llvm-*/lib", "/usr/lib64/llvm*/lib", "/opt/homebrew/Cellar/llvm/*/lib")
_NAME = re.compile(r"^libLLVM(?:-(\d+)(?:\.\d+)*\.(?:so|dylib)(?:\.\d+)*|\.so\.(\d+)(?:\.\d+)*"
                   r"|\.(\d+)(?:\.\d+)*\.dylib)$")
_DIR_VERSION = re.compile(r"llvm[-@]?(\d+)")


def llvm_version(path: str | Path) -> int | None:
    """LLVM major version encoded in a library's file name (or its folder), if any."""
    path = Path(path)
    match = _NAME.match(path.name)
    if match:
        found = next((g for g in match.groups() if g), None)
        if found:
            return int(found)
    if path.name in ("libLLVM.so", "libLLVM.dylib"):
        folder = _DIR_VERSION.search(str(path.parent).lower())
        if folder:
            return int(folder.group(1))
    return None


def candidate_libraries(dirs: Iterable[str] | None = None) -> list[tuple[int, str]]:
    """(major version, path) of every libLLVM found, newest first."""
    if dirs is None:
        dirs = list(_DIRS) + sorted(d for pattern in _DIR_GLOBS for d in glob.glob(pattern))
    found: dict[str, int] = {}
    for folder in dirs:
        for path in glob.glob(os.path.join(folder, "libLLVM*")):
            version = llvm_version(path)
            if version is not None and os.path.isfile(path):
                found.setdefault(os.path.realpath(path), version)
                found.setdefault(path, version)
    ranked = sorted(((v, p) for p, v in found.items()), key=lambda vp: (-vp[0], len(vp[1])))
    return ranked


def find_libllvm(env: Mapping[str, str] | None = None,
                 dirs: Iterable[str] | None = None) -> str:
    """The LLVM library Dr.Jit should load: ``DRJIT_LIBLLVM_PATH`` if set, else the newest >= 16.

    Raises a one-line :class:`PluginError` saying what to install when none is found.
    """
    env = os.environ if env is None else env
    chosen = env.get(ENV_VAR)
    if chosen:
        if not os.path.isfile(chosen):
            raise PluginError(f"mitsuba simulator: {ENV_VAR}={chosen} does not exist; "
                              f"{INSTALL_HINT}")
        return chosen
    candidates = [(v, p) for v, p in candidate_libraries(dirs) if v >= MIN_VERSION]
    if not candidates:
        searched = ", ".join(dirs) if dirs is not None else "the usual library folders"
        raise PluginError(f"mitsuba simulator: no LLVM >= {MIN_VERSION} library found in "
                          f"{searched} (LLVM 15 crashes Dr.Jit); {INSTALL_HINT}")
    return candidates[0][1]


def llvm_problem() -> str:
    """Why Dr.Jit would find no usable LLVM here, in one line ('' when it would): the
    mitsuba plugin's system check (the conformance kit skips it with this reason)."""
    try:
        find_libllvm()
    except PluginError as err:
        return str(err)
    return ""


def configure_llvm(env: MutableMapping[str, str] | None = None,
                   dirs: Iterable[str] | None = None) -> str:
    """Set ``DRJIT_LIBLLVM_PATH`` (unless set) before Dr.Jit is imported; return the library.

    Once Dr.Jit is imported it has made its choice; then the variable is left
    as it is and its value (possibly empty) is returned.
    """
    env = os.environ if env is None else env
    if "drjit" in sys.modules and env is os.environ:
        return env.get(ENV_VAR, "")
    path = find_libllvm(env, dirs)
    env[ENV_VAR] = path
    return path

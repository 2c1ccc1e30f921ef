"""The capture-format interface: readers (and writers) of capture files, as plugins.

A :class:`CaptureFormat` recognises its files by their content (:meth:`~CaptureFormat.detect`,
never by their name), reads one into a :class:`~nlosfw.capture.Capture`, may write one
(capability ``writable``), and may propose default preprocessing for a file (for example
the LCT format's gate that removes the direct reflection, as its authors' code does).
Formats register through the ``register_capture_formats`` hook; the run's
``capture.format`` forces one, else :func:`detect_format` picks the one that claims the file.
"""

from __future__ import annotations

import sys
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, TypeVar

from nlosfw.capture.data import Capture
from nlosfw.capture.preprocess import Preprocessing
from nlosfw.common.config import Configurable
from nlosfw.common.errors import DataError, PluginError
from nlosfw.common.inputs import regular_file


@dataclass(frozen=True)
class CaptureFormatConfig:
    """Options shared by every capture format (none yet)."""


FormatConfigT = TypeVar("FormatConfigT", bound=CaptureFormatConfig)


class CaptureFormat(Configurable[FormatConfigT], ABC):
    """Reads (and optionally writes) capture files of one layout."""

    config_class: ClassVar[type] = CaptureFormatConfig

    @abstractmethod
    def detect(self, path: Path) -> bool:
        """Whether ``path``'s content is in this format; cheap (names and attributes, not
        the data), never raising: anything unreadable is simply not this format's."""

    @abstractmethod
    def read(self, path: Path) -> Capture:
        """The capture in ``path``; a one-line DataError naming the file, the missing or bad
        variable and what was expected otherwise (also for a file of another format)."""

    def write(self, path: Path, capture: Capture) -> Path:
        """Write ``capture`` to ``path`` (formats with the ``writable`` capability); never
        overwrites an existing file, and leaves nothing behind on failure."""
        raise PluginError(f"capture format {type(self).__name__} cannot write files")

    def transient_shape(self, path: Path) -> tuple[int, int, int] | None:
        """(time bins, sensor points, laser points) of ``path``'s transient from the file's
        header, no data read (for the memory estimate before a run); None when the format
        cannot tell."""
        return None

    def defaults(self, path: Path) -> Preprocessing:
        """The preprocessing this format applies to ``path`` unless the run's options say
        otherwise (none by default)."""
        return Preprocessing()


def detect_format(path: Path, formats: Mapping[str, CaptureFormat]) -> str:
    """The name of the one format in ``formats`` that claims ``path``.

    A one-line error naming the file and the supported formats when none does, naming the
    claimants when several do (ConfigError ``capture.path`` for a missing file).
    """
    names = ", ".join(sorted(formats))
    regular_file(path, "capture.path")
    claimed = []
    for name, fmt in sorted(formats.items()):
        try:
            if fmt.detect(path):
                claimed.append(name)
        except Exception:  # a detector must not break detection of the others
            continue
    if not claimed:
        _refuse_unreadable(path)
        raise DataError(f"{path}: not a capture file of any supported format; supported: "
                        f"{names} (force one with capture.format=NAME)")
    if len(claimed) > 1:
        raise DataError(f"{path}: claimed by several capture formats: {', '.join(claimed)}; "
                        "choose one with capture.format=NAME")
    return claimed[0]


def _refuse_unreadable(path: Path) -> None:
    """DataError for an HDF5 or MATLAB file (7.3 or 5) that cannot be read: damaged
    (truncated), or holding links or data outside the file; nothing for other files."""
    from nlosfw.capture.matfile import is_hdf5, mat_variables, mat_version

    if is_hdf5(path) or mat_version(path) == 5:
        mat_variables(path)


def read_with(fmt: CaptureFormat, name: str, path: Path) -> Capture:
    """``fmt.read(path)``, every failure a one-line DataError naming the file (and the
    format when the reader's own message does not). Raises the audit event
    ``nlosfw.capture.read`` (path, format) first: one per full read of a capture file."""
    sys.audit("nlosfw.capture.read", str(path), name)
    try:
        return fmt.read(path)
    except DataError as err:
        text = str(err)
        if str(path) not in text:
            text = f"{path}: {text}"
        raise DataError(text) from None
    except (OSError, ValueError, KeyError, TypeError, IndexError) as err:
        raise DataError(f"{path}: cannot be read as a {name} capture ({type(err).__name__}: "
                        f"{err})".replace("\n", " ")) from None

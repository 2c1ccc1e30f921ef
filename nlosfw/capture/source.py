"""The capture of a file: its format (forced or detected), reading, preprocessing.

A capture file is opened once (:func:`open_capture`, through
:func:`~nlosfw.common.reading.read_once`): its format detected once, its header read
once (:meth:`CaptureFile.transient_shape`, for the memory estimate before the data is
read), then read and preprocessed once (:meth:`CaptureFile.load`) and hashed from the
same descriptor (the cache key). A run's plan does this before anything is written, so
that a bad file or option ends with one line before any output exists, and the capture
stage uses the capture the plan read. The options are ``capture.*``
(:class:`CaptureSource`); a format's defaults
(:meth:`~nlosfw.capture.CaptureFormat.defaults`) fill the options the run leaves unset,
and every step applied is recorded with its source. The installed formats come as a
:class:`FormatCatalogue` (the plugin registry builds it), so this stage needs no plugin
machinery. Every full read of a capture file raises the audit event
``nlosfw.capture.read`` (:func:`sys.audit`) with the file's path and format.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.formats import CaptureFormat, detect_format, read_with
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.capture.preprocess import AppliedStep, Extras, Preprocessing, preprocess
from nlosfw.capture.scan import on_scan_grid
from nlosfw.common.config import require
from nlosfw.common.errors import ConfigError, DataError, one_line
from nlosfw.common.hashing import cache_key, file_digest
from nlosfw.common.inputs import regular_file
from nlosfw.common.reading import OpenedFile, read_once

#: What a cache key of a preprocessed capture covers (JSON-like values).
KeyMaterial = dict[str, object]


@dataclass(frozen=True)
class CaptureSource(Preprocessing):
    """Where the capture comes from, and its preprocessing (the fields of
    :class:`~nlosfw.capture.Preprocessing`: gate, time_crop, bin, stride, flip, transpose,
    bin_width, tofgrid, background, pileup_pulses), applied to a file's capture and to a
    simulated one."""

    path: str | None = None
    """Read this capture file instead of simulating; its format is detected from its content."""
    format: str | None = None
    """Force a capture format (a ``capture_format`` plugin: nlosfw, ytal, znlos, lct, fk,
    wisconsin, ...); null: the one that recognises the file."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.format is None or self.path is not None, "format",
                "forces the format of capture.path: give capture.path too")

    @property
    def options(self) -> Preprocessing:
        """The preprocessing options alone."""
        return Preprocessing(**{f.name: getattr(self, f.name)
                                for f in dataclasses.fields(Preprocessing)})


@dataclass(frozen=True)
class FormatCatalogue:
    """The installed capture formats: a factory per registered name, and the names whose
    requirements are installed (the ones detection asks)."""

    factories: Mapping[str, Callable[[], CaptureFormat]]
    installed: frozenset[str]

    def names(self) -> list[str]:
        return sorted(self.factories)

    def create(self, name: str) -> CaptureFormat:
        """The format ``name`` (a one-line ConfigError for ``capture.format`` when unknown)."""
        if name not in self.factories:
            raise ConfigError("capture.format", f"unknown capture format '{name}'; valid: "
                                                f"{', '.join(self.names())}")
        return self.factories[name]()

    def choose(self, path: Path, forced: str | None) -> tuple[str, CaptureFormat]:
        """``forced`` (``capture.format``) or the one installed format that claims ``path``."""
        if forced is not None:
            return forced, self.create(forced)
        installed = {name: self.create(name) for name in sorted(self.installed)}
        name = detect_format(path, installed)
        return name, installed[name]


@dataclass(frozen=True, eq=False)
class Prepared:
    """A preprocessed capture, the steps applied, and what the cache key must cover."""

    capture: Capture
    steps: tuple[AppliedStep, ...]
    key_material: KeyMaterial


@dataclass(frozen=True, eq=False)
class FileCapture:
    """A capture read from a file (``format`` read it) and preprocessed; ``digest`` is the
    SHA-256 of the file's bytes, hashed through the descriptor that read it."""

    path: Path
    format: str
    prepared: Prepared
    digest: str

    def cache_key(self, reader_version: str) -> str:
        """Key of the preprocessed capture: the file's bytes, its format and the reader's
        version, every step's value, and the bytes of the files the steps read."""
        return cache_key({"file": self.digest, "format": self.format,
                          "reader": reader_version, **self.prepared.key_material})


@dataclass(frozen=True, eq=False)
class CaptureFile:
    """A capture file open (:func:`open_capture`), its format chosen: what can be asked of
    it before it is read, and its one read."""

    path: Path
    format: str
    reader: CaptureFormat
    source: CaptureSource
    formats: FormatCatalogue
    opened: OpenedFile

    def transient_shape(self) -> tuple[int, int, int] | None:
        """(time bins, sensor points, laser points) from the format's reading of the header
        (for the memory estimate before the data is read); None when it cannot tell."""
        try:
            return self.reader.transient_shape(self.path)
        except (ConfigError, DataError):
            return None

    def load(self) -> FileCapture:
        """The capture read (once) and preprocessed: the run's options over the format's
        defaults; the file's digest from the same descriptor."""
        capture = read_with(self.reader, self.format, self.path)
        options, from_format = self.source.options.merged_over(self.reader.defaults(self.path))
        prepared = prepare(capture, options, from_format, self.formats, self.path)
        return FileCapture(path=self.path, format=self.format, prepared=prepared,
                           digest=self.opened.digest())


@contextmanager
def open_capture(source: CaptureSource, formats: FormatCatalogue) -> Iterator[CaptureFile]:
    """``source.path`` open for the block, its format forced or detected (once): a one-line
    error when it is missing, not a regular file, unreadable or of no format."""
    if source.path is None:
        raise ConfigError("capture.path", "no capture file given")
    path = regular_file(source.path, "capture.path")
    with ExitStack() as stack:
        opened = stack.enter_context(_opened(path))
        name, fmt = formats.choose(path, source.format)
        yield CaptureFile(path=path, format=name, reader=fmt, source=source,
                          formats=formats, opened=opened)


@contextmanager
def _opened(path: Path) -> Iterator[OpenedFile]:
    """:func:`~nlosfw.common.reading.read_once`, a file that cannot be opened a one-line
    DataError."""
    try:
        stack = ExitStack()
        opened = stack.enter_context(read_once(path))
    except OSError as err:
        raise DataError(f"{path}: cannot be read ({err.strerror or one_line(err)})") from None
    with stack:
        yield opened


def read_capture_file(path: Path, forced: str | None, formats: FormatCatalogue
                      ) -> tuple[str, CaptureFormat, Capture]:
    """The format of ``path`` and the capture it reads there (no preprocessing), the file
    opened once."""
    regular_file(path, "capture.path")
    with _opened(path):
        name, fmt = formats.choose(path, forced)
        return name, fmt, read_with(fmt, name, path)


def load_file_capture(source: CaptureSource, formats: FormatCatalogue) -> FileCapture:
    """Read ``source.path`` (format forced or detected) and preprocess it: the run's options
    over the format's defaults (the file opened once)."""
    with open_capture(source, formats) as file:
        return file.load()


def prepare(capture: Capture, options: Preprocessing, from_format: frozenset[str],
            formats: FormatCatalogue, origin: Path | None = None) -> Prepared:
    """Preprocess ``capture`` (read from ``origin``, if a file): load the per-pixel delays
    and the background the options name, apply every step, and say what the cache key of
    the result must cover."""
    material: KeyMaterial = {}
    delays = None
    if options.tofgrid:
        tof = _existing(options.tofgrid, "tofgrid")
        delays = _delays(tof, capture, origin)
        material["tofgrid"] = file_digest(tof)
    background = None
    if options.background:
        bg_path = _existing(options.background, "background")
        if origin is not None and bg_path.resolve() == origin.resolve():
            raise ConfigError("capture.background", f"{options.background} is the capture file "
                                                    "itself; give the background measurement")
        with _opened(bg_path):                  # read and hashed through one descriptor
            _, _, background = read_capture_file(bg_path, None, formats)
            material["background"] = file_digest(bg_path)
    source = "the capture" if origin is None else str(origin)
    result, steps = preprocess(capture, options, from_format, Extras(delays, background, source))
    material["steps"] = [[s.option, s.value] for s in steps]
    return Prepared(result, steps, material)


def _existing(value: str, option: str) -> Path:
    return regular_file(value, f"capture.{option}")


def _delays(tof: Path, capture: Capture, origin: Path | None) -> np.ndarray:
    """The per-pixel delays (ps) of ``tof`` on the capture's scan grid (X, Y)."""
    from nlosfw.capture.fk import TOF_VARIABLE, read_tofgrid, tofgrid_shape

    declared = tofgrid_shape(tof)
    if declared is not None and len(declared) == 2:     # its header, before reading it
        _check_tofgrid_shape(tof, declared, capture, origin)
    try:
        raw = read_tofgrid(tof)
    except DataError as err:
        raise ConfigError("capture.tofgrid", str(err)) from None
    _check_tofgrid_shape(tof, raw.shape, capture, origin)
    delays = on_scan_grid(capture, raw)
    bin_ps = capture.delta_t / (SPEED_OF_LIGHT * 1e-12)
    if float(np.max(raw, initial=0.0)) >= capture.n_bins * bin_ps:
        raise ConfigError("capture.tofgrid", f"{tof}: variable '{TOF_VARIABLE}' holds delays up "
                                             f"to {float(np.max(raw)):g} ps, beyond the "
                                             f"capture's {capture.n_bins} bins of {bin_ps:g} ps")
    return delays


def _check_tofgrid_shape(tof: Path, shape: tuple[int, ...], capture: Capture,
                         origin: Path | None) -> None:
    """Delays of ``shape`` (MATLAB's ``[i, j]``) must cover the capture's scan grid."""
    from nlosfw.capture.fk import TOF_VARIABLE

    on_grid = on_scan_grid(capture, np.broadcast_to(np.float64(0), shape)).shape  # no data
    if on_grid != capture.grid_shape:
        of = f" of {origin}" if origin is not None else ""
        raise ConfigError("capture.tofgrid", f"{tof}: variable '{TOF_VARIABLE}' has shape "
                                             f"{list(shape)}; expected "
                                             f"{list(capture.grid_shape)}, the scan grid{of}")

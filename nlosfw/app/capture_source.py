"""The run's capture from a file: its format (forced or detected), reading, preprocessing.

Used twice with the same code: by the command line's preflight, so that a bad file or
option ends with one line before any output exists, and by the pipeline's capture stage.
The options are ``capture.*`` (:class:`~nlosfw.app.settings.CaptureSource`); a format's
defaults (:meth:`~nlosfw.capture.CaptureFormat.defaults`) fill the options the run
leaves unset, and every step applied is recorded with its source.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nlosfw.app.cache import cache_key, file_digest
from nlosfw.app.settings import CaptureSource
from nlosfw.capture.data import Capture
from nlosfw.capture.formats import CaptureFormat, detect_format, read_with
from nlosfw.capture.preprocess import AppliedStep, Extras, Preprocessing, preprocess
from nlosfw.capture.scan import on_scan_grid
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.plugins import PluginHost, PluginKind

_KIND = PluginKind.CAPTURE_FORMAT


@dataclass(frozen=True, eq=False)
class Prepared:
    """A preprocessed capture, the steps applied, and what the cache key must cover."""

    capture: Capture
    steps: tuple[AppliedStep, ...]
    key_material: dict[str, Any]


@dataclass(frozen=True, eq=False)
class FileCapture:
    """A capture read from a file (``format`` read it) and preprocessed."""

    path: Path
    format: str
    prepared: Prepared

    def cache_key(self, reader_version: str) -> str:
        """Key of the preprocessed capture: the file's bytes, its format and the reader's
        version, every step's value, and the bytes of the files the steps read."""
        return cache_key({"file": file_digest(self.path), "format": self.format,
                          "reader": reader_version, **self.prepared.key_material})


def capture_formats(host: PluginHost) -> dict[str, CaptureFormat]:
    """Every installed capture format (with its default options), by name."""
    formats = {}
    for spec in host.registry.specs(_KIND):
        if spec.missing_requirements():
            continue
        formats[spec.name] = spec.create({})
    return formats


def choose_format(path: Path, forced: str | None, host: PluginHost) -> tuple[str, CaptureFormat]:
    """``forced`` (``capture.format``) or the one format that claims ``path``."""
    if forced is not None:
        if (_KIND, forced) not in host.registry:
            valid = ", ".join(host.registry.names(_KIND))
            raise ConfigError("capture.format", f"unknown capture format '{forced}'; valid: "
                                                f"{valid}")
        return forced, host.registry.create(_KIND, forced, {})
    name = detect_format(path, capture_formats(host))
    return name, host.registry.create(_KIND, name, {})


def file_transient_shape(path: Path, forced: str | None, host: PluginHost
                         ) -> tuple[int, int, int] | None:
    """(time bins, sensor points, laser points) of a capture file from its format's reading
    of the header (for the memory estimate); None when the file or its format cannot tell
    (reading the file says why)."""
    try:
        return choose_format(path, forced, host)[1].transient_shape(path)
    except (ConfigError, DataError):
        return None


def read_capture_file(path: Path, forced: str | None, host: PluginHost
                      ) -> tuple[str, CaptureFormat, Capture]:
    """The format of ``path`` and the capture it reads there (no preprocessing)."""
    if not path.is_file():
        raise ConfigError("capture.path", f"file not found: {path}")
    name, fmt = choose_format(path, forced, host)
    return name, fmt, read_with(fmt, name, path)


def load_file_capture(source: CaptureSource, host: PluginHost) -> FileCapture:
    """Read ``source.path`` (format forced or detected) and preprocess it: the run's options
    over the format's defaults."""
    if source.path is None:
        raise ConfigError("capture.path", "no capture file given")
    path = Path(source.path).expanduser()
    name, fmt, capture = read_capture_file(path, source.format, host)
    options, from_format = options_of(source).merged_over(fmt.defaults(path))
    return FileCapture(path=path, format=name,
                       prepared=prepare(capture, options, from_format, host, path))


def options_of(source: CaptureSource) -> Preprocessing:
    """The preprocessing options of ``capture.*``."""
    return Preprocessing(**{f.name: getattr(source, f.name)
                            for f in dataclasses.fields(Preprocessing)})


def prepare(capture: Capture, options: Preprocessing, from_format: frozenset[str],
            host: PluginHost, origin: Path | None = None) -> Prepared:
    """Preprocess ``capture`` (read from ``origin``, if a file): load the per-pixel delays
    and the background the options name, apply every step, and say what the cache key of
    the result must cover."""
    material: dict[str, Any] = {}
    delays = None
    if options.tofgrid:
        tof = _existing(options.tofgrid, "tofgrid")
        delays = _delays(tof, capture, origin)
        material["tofgrid"] = file_digest(tof)
    background = None
    if options.background:
        bg_path = _existing(options.background, "background")
        _, _, background = read_capture_file(bg_path, None, host)
        material["background"] = file_digest(bg_path)
    result, steps = preprocess(capture, options, from_format, Extras(delays, background))
    material["steps"] = [[s.option, s.value] for s in steps]
    return Prepared(result, steps, material)


def check_files(options: Preprocessing, host: PluginHost) -> None:
    """The files the options name exist and are readable (a simulated run's preflight:
    their shapes are checked against the capture once it is simulated)."""
    if options.tofgrid:
        from nlosfw.capture.fk import read_tofgrid

        read_tofgrid(_existing(options.tofgrid, "tofgrid"))
    if options.background:
        read_capture_file(_existing(options.background, "background"), None, host)


def _existing(value: str, option: str) -> Path:
    path = Path(value).expanduser()
    if not path.is_file():
        raise ConfigError(f"capture.{option}", f"file not found: {value}")
    return path


def _delays(tof: Path, capture: Capture, origin: Path | None) -> Any:
    """The per-pixel delays (ps) of ``tof`` on the capture's scan grid (X, Y)."""
    from nlosfw.capture.fk import TOF_VARIABLE, read_tofgrid

    try:
        raw = read_tofgrid(tof)
    except DataError as err:
        raise ConfigError("capture.tofgrid", str(err)) from None
    delays = on_scan_grid(capture, raw)
    if delays.shape != capture.grid_shape:
        of = f" of {origin}" if origin is not None else ""
        raise ConfigError("capture.tofgrid", f"{tof}: variable '{TOF_VARIABLE}' has shape "
                                             f"{list(raw.shape)}; expected "
                                             f"{list(capture.grid_shape)}, the scan grid{of}")
    return delays

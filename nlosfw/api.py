"""The Python API: one function per stage of a run, and :func:`run` for a whole run.

Each stage function takes a plugin by name and its options as keyword arguments, checked
as the command line checks them (an unknown option or a bad value is a one-line
:class:`~nlosfw.common.errors.ConfigError`)::

    import numpy as np
    import nlosfw

    capture = nlosfw.simulate_scene("thesis_two_planes")             # or nlosfw.load_capture(path)
    field = nlosfw.transform_capture(capture, "fft", n_frequencies=51)
    split = nlosfw.split_field(field, spatial_step=2)
    model = nlosfw.fit_model(split.train_field, "siren_torch", steps=500)
    predicted = nlosfw.predict_field(model, field)
    depths = np.linspace(*nlosfw.depth_span(capture), 16)
    image = nlosfw.reconstruct(predicted, depths, "fft")             # a Reconstruction

    out = nlosfw.run(["model=interp", "scene=letter_t"])            # the whole pipeline
    out.metrics.field["interp"].splits.heldout_pixels.nmse_db

Importing this module loads no Hydra, matplotlib or backend: plugins load when a function
needs one, and :func:`run` imports Hydra (to compose the configuration) when called.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nlosfw.capture import Capture
from nlosfw.common import ConfigError
from nlosfw.common.config import config_from_mapping
from nlosfw.image import Reconstruction, wall_voxels
from nlosfw.model import FieldModel
from nlosfw.plugins import PluginHost, PluginKind, current_host
from nlosfw.simulate import Scene, builtin_scene, scene_from_config
from nlosfw.transform import PhasorField

if TYPE_CHECKING:
    from nlosfw.pipeline import RunOutput

log = logging.getLogger(__name__)


def simulate_scene(scene: Scene | str | Mapping[str, object], simulator: str = "analytic",
                   **options: object) -> Capture:
    """The transient capture of ``scene`` rendered by simulator plugin ``simulator``.

    ``scene`` is a :class:`~nlosfw.simulate.Scene`, the name of a built-in scene
    (``thesis_two_planes``, ``letter_t``, ...) or a scene mapping as in ``conf/scene/``;
    ``options`` are the simulator's (``samples=65536`` for ``embree``). Noise the scene
    asks for is added.
    """
    scene = _scene(scene)
    name = _plugin(PluginKind.SIMULATOR, simulator, "simulator")
    return _host().registry.create(PluginKind.SIMULATOR, name, options).simulate(scene)


def load_capture(path: str | Path, format: str | None = None,
                 **preprocessing: Any) -> Capture:
    """The capture in file ``path``, as a run with ``capture.path=PATH`` reads it.

    Every installed capture format reads it (``lct``, ``fk``, ``znlos``, ``ytal``,
    ``wisconsin``, nlosfw's own HDF5, ...), detected from the file's content or forced with
    ``format``; the format's default preprocessing applies, and ``preprocessing`` overrides
    it with the options of ``capture.*``: ``gate=600`` (bins; or ``gate={"metres": 1.2}``),
    ``time_crop=(0, 512)`` (bins; or ``time_crop={"metres": [0.5, 3.0]}``), ``bin=2``,
    ``stride=2``, ``flip="x"``, ``transpose=True``, ``bin_width={"ps": 4}``,
    ``tofgrid="tof.mat"``, ``background="empty.hdf5"``, ``pileup_pulses=1000``.
    A bad file is a one-line :class:`~nlosfw.common.errors.NlosfwError`, a bad option a
    :class:`~nlosfw.common.errors.ConfigError` naming it (``capture.gate.bins: ...``).
    """
    from nlosfw.capture.source import CaptureSource, load_file_capture

    valid = {f.name for f in dataclasses.fields(CaptureSource)} - {"path", "format"}
    options: dict[str, object] = {"path": _file_path(path, "capture.path"),
                                  "format": _name(format, "capture.format", optional=True)}
    for key, value in preprocessing.items():
        if key not in valid:
            raise ConfigError(f"capture.{key}", f"unknown preprocessing option; valid: "
                                                f"{', '.join(sorted(valid))}")
        if value is not None:
            options[key] = _preprocessing_value(key, value)
    source = config_from_mapping(CaptureSource, options, "capture")
    return load_file_capture(source, _host().capture_formats()).prepared.capture


#: The unit a plain value of a preprocessing option's group stands for: ``gate=600`` is
#: ``gate={"bins": 600}``, ``time_crop=(0, 512)`` is ``time_crop={"bins": [0, 512]}``.
_SHORTHAND = {"gate": "bins", "time_crop": "bins"}
#: The preprocessing options that name files.
_FILES = ("tofgrid", "background")


def _preprocessing_value(key: str, value: object) -> object:
    """``value`` of preprocessing option ``key`` as ``capture.*`` takes it."""
    if key in _FILES:
        empty = isinstance(value, str) and not value                       # '': none
        return "" if empty else _file_path(value, f"capture.{key}")
    if key in _SHORTHAND and not isinstance(value, Mapping) and not \
            dataclasses.is_dataclass(value):
        plain = list(value) if isinstance(value, (tuple, list, np.ndarray)) else value
        return {_SHORTHAND[key]: plain}
    return value


def _file_path(value: object, option: str) -> str:
    """A path given as ``str`` or ``os.PathLike``; a ConfigError naming ``option`` else."""
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    if not isinstance(value, str) or not value:
        raise ConfigError(option, f"expected a path (str or pathlib.Path), got "
                                  f"{_shown(value)}")
    return value


def _name(value: object, option: str, optional: bool = False) -> str | None:
    """A plugin's (or a format's) name; a ConfigError naming ``option`` for anything but
    a string (None too, unless ``optional``)."""
    if value is None and optional:
        return None
    if not isinstance(value, str):
        raise ConfigError(option, f"expected a name (str), got {_shown(value)}")
    return value


def _of_type(value: object, kind: type, option: str, what: str) -> None:
    """A ConfigError naming ``option`` unless ``value`` is a ``kind``."""
    if not isinstance(value, kind):
        raise ConfigError(option, f"expected {what}, got {_shown(value)}")


def _shown(value: object) -> str:
    """``value`` in a message: its repr (shortened) and its type."""
    text = repr(value)
    return f"{text[:60]}... ({type(value).__name__})" if len(text) > 60 else \
        f"{text} ({type(value).__name__})"


def transform_capture(capture: Capture, transform: str = "fft", **options: object) -> PhasorField:
    """The phasor field of ``capture`` (values ``[frequency, y, x]``) by transform plugin
    ``transform`` (``fft``, ``wavelet``) with its ``options`` (``n_frequencies=51``); a band
    that aliases on the wall grid logs its warning (:func:`nlosfw.transform.band_warning`)."""
    from nlosfw.transform.frequencies import band_warning

    _of_type(capture, Capture, "capture", "a Capture")
    name = _plugin(PluginKind.PHASOR_TRANSFORM, transform, "transform")
    field = _host().registry.create(PluginKind.PHASOR_TRANSFORM, name, options).transform(
        capture)
    warning = band_warning(field)
    if warning is not None:
        log.warning("%s", warning)
    return field


def fit_model(field: PhasorField, model: str = "interp", **options: object) -> FieldModel:
    """Field model plugin ``model`` with ``options`` (``steps=500``), fitted to ``field``.

    Fit it to the training part of a split (:func:`nlosfw.evaluation.split_field`) to score it
    on the held-out samples afterwards (:func:`nlosfw.evaluation.field_metrics`). For the fit's
    report (steps, seconds, losses), create the plugin and call its ``fit`` yourself.
    """
    _of_type(field, PhasorField, "field", "a PhasorField")
    fitted = _host().registry.create(
        PluginKind.FIELD_MODEL, _plugin(PluginKind.FIELD_MODEL, model, "model"), options)
    fitted.fit(field)
    return fitted


def predict_field(model: FieldModel, like: PhasorField) -> PhasorField:
    """The fitted ``model``'s field at the wall samples, frequencies, geometry and spectral
    weights of ``like`` (typically the full field a split came from)."""
    _of_type(model, FieldModel, "model", "a fitted FieldModel (nlosfw.fit_model's)")
    _of_type(like, PhasorField, "like", "a PhasorField")
    return model.predict_field(like.wall_xyz, like.frequencies, like.geometry, like.weights)


def reconstruct(field: PhasorField, depths: Sequence[float] | np.ndarray,
                imager: str = "fft", *, grid: PhasorField | None = None,
                **options: object) -> Reconstruction:
    """Image ``field`` with imager plugin ``imager`` (and its ``options``) on planes at
    ``depths`` (m) facing the wall samples of ``grid`` (default: the field's own), as a
    run does (see :func:`nlosfw.image.wall_voxels`).

    Pass the full field as ``grid`` to image a subsampled field on the full field's
    voxels, so that their images compare pixel by pixel. :func:`nlosfw.image.depth_span`
    gives the depths a capture's hidden scene spans, and
    :func:`nlosfw.image.automatic_depths` the planes a run images there by default; for
    other voxels call the imager itself
    (``load_plugins().registry.create("imager", "rsd").reconstruct(field, voxels)``).
    """
    _of_type(field, PhasorField, "field", "a PhasorField")
    if grid is not None:
        _of_type(grid, PhasorField, "grid", "a PhasorField (or None: the field's own)")
    planes = _depths(depths)
    voxels = wall_voxels(field if grid is None else grid, planes)
    name = _plugin(PluginKind.IMAGER, imager, "imager")
    return _host().registry.create(PluginKind.IMAGER, name, options).reconstruct(field, voxels)


def _depths(depths: object) -> np.ndarray:
    """``depths`` as finite positive metres (one or more); a ConfigError naming them else."""
    try:
        planes = np.asarray(depths, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError("depths", f"expected depths in metres (numbers), got "
                                    f"{_shown(depths)}") from None
    if planes.size == 0 or not np.all(np.isfinite(planes)) or not np.all(planes > 0):
        raise ConfigError("depths", f"need one or more finite depths > 0 (m, in front of the "
                                    f"wall), got {planes.tolist()[:8]}")
    return planes


def run(overrides: Sequence[str] = (), *, output_dir: str | Path | None = None,
        config_name: str = "config") -> RunOutput:
    """One run of the pipeline, exactly as ``python -m nlosfw OVERRIDES...`` runs it.

    ``overrides`` are the command line's (``["scene=letter_t", "model=siren_torch",
    "model.steps=500"]``), checked before anything is written; a mistake raises the
    error the command line would print (:class:`~nlosfw.common.errors.ConfigError`,
    :class:`~nlosfw.common.errors.PluginError`, ...). Sweeps (``model=a,b``) are one
    call per value. The run writes into ``output_dir`` (created; it must be new or
    empty) or, by default, a new temporary directory; either way ``.dir`` of the result
    names it, with ``report.html`` and the figures. ``config_name`` is the command
    line's ``-cn``.

    Returns the run's :class:`~nlosfw.pipeline.results.RunOutput`: ``.metrics`` (the
    :class:`~nlosfw.pipeline.metrics.RunMetrics` of metrics.json), ``.results`` (the typed
    :class:`~nlosfw.pipeline.results.RunResults`: capture, phasor field, fitted models,
    predicted fields, reconstructions), ``.config`` and ``.dir``.
    """
    from nlosfw.common.resources import config_dir
    from nlosfw.compose import run_in_process

    if isinstance(overrides, str) or not isinstance(overrides, Sequence):
        shown = (f"the string {overrides!r} (write [{overrides!r}])"
                 if isinstance(overrides, str) else _shown(overrides))
        raise ConfigError("overrides", f"expected a list of overrides, got {shown}")
    for i, text in enumerate(overrides):
        _of_type(text, str, f"overrides[{i}]", "an override such as 'model=interp' (str)")
    if output_dir is not None:
        output_dir = _file_path(output_dir, "output_dir")
    _name(config_name, "config_name")
    primary = sorted(p.stem for p in config_dir().glob("*.yaml"))
    if config_name not in primary:
        raise ConfigError("config_name", f"no primary configuration {config_name!r}; valid: "
                                         f"{', '.join(primary)}")
    return run_in_process(overrides, output_dir, config_name)


def _scene(scene: Scene | str | Mapping[str, object]) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, str):
        return builtin_scene(scene)
    if isinstance(scene, Mapping):
        return scene_from_config(scene)
    raise ConfigError("scene", f"expected a Scene, a built-in scene's name or a mapping, got "
                      f"{type(scene).__name__}")


def _plugin(kind: PluginKind, name: object, option: str) -> str:
    """The plugin name ``name`` of ``kind``; a ConfigError naming ``option`` (the function's
    keyword) for a name that is not a string or not a plugin of that kind."""
    known = _host().registry.names(kind)
    if _name(name, option) not in known:
        raise ConfigError(option, f"unknown {kind.value} plugin {name!r}; valid: "
                                  f"{', '.join(known)}")
    return str(name)


def _host() -> PluginHost:
    """The plugin host of the run in progress (:func:`nlosfw.plugins.hosting`), else a new one."""
    return current_host()

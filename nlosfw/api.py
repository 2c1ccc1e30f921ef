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

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nlosfw.capture import Capture
from nlosfw.common import ConfigError
from nlosfw.image import Reconstruction, wall_voxels
from nlosfw.model import FieldModel
from nlosfw.plugins import PluginHost, PluginKind, load_plugins
from nlosfw.simulate import Scene, builtin_scene, scene_from_config
from nlosfw.transform import PhasorField

if TYPE_CHECKING:
    from nlosfw.pipeline import RunOutput


def simulate_scene(scene: Scene | str | Mapping[str, object], simulator: str = "analytic",
                   **options: object) -> Capture:
    """The transient capture of ``scene`` rendered by simulator plugin ``simulator``.

    ``scene`` is a :class:`~nlosfw.simulate.Scene`, the name of a built-in scene
    (``thesis_two_planes``, ``letter_t``, ...) or a scene mapping as in ``conf/scene/``;
    ``options`` are the simulator's (``samples=65536`` for ``embree``). Noise the scene
    asks for is added.
    """
    plugin = _host().registry.create(PluginKind.SIMULATOR, simulator, options)
    return plugin.simulate(_scene(scene))


def load_capture(path: str | Path, format: str | None = None,
                 **preprocessing: Any) -> Capture:
    """The capture in file ``path``, as a run with ``capture.path=PATH`` reads it.

    Every installed capture format reads it (``lct``, ``fk``, ``znlos``, ``ytal``,
    ``wisconsin``, nlosfw's own HDF5, ...), detected from the file's content or forced with
    ``format``; the format's default preprocessing applies, and ``preprocessing`` overrides
    it with the options of ``capture.*`` (``gate=600``, ``bin=2``, ``tofgrid="tof.mat"``).
    A bad file or option is a one-line :class:`~nlosfw.common.errors.NlosfwError`.
    """
    import dataclasses

    from nlosfw.capture.source import CaptureSource, load_file_capture

    valid = {f.name for f in dataclasses.fields(CaptureSource)} - {"path", "format"}
    for key in preprocessing:
        if key not in valid:
            raise ConfigError(f"capture.{key}", f"unknown preprocessing option; valid: "
                                                f"{', '.join(sorted(valid))}")
    source = CaptureSource(path=str(path), format=format, **preprocessing)
    return load_file_capture(source, _host().capture_formats()).prepared.capture


def transform_capture(capture: Capture, transform: str = "fft", **options: object) -> PhasorField:
    """The phasor field of ``capture`` (values ``[frequency, y, x]``) by transform plugin
    ``transform`` (``fft``, ``wavelet``) with its ``options`` (``n_frequencies=51``)."""
    plugin = _host().registry.create(PluginKind.PHASOR_TRANSFORM, transform, options)
    return plugin.transform(capture)


def fit_model(field: PhasorField, model: str = "interp", **options: object) -> FieldModel:
    """Field model plugin ``model`` with ``options`` (``steps=500``), fitted to ``field``.

    Fit it to the training part of a split (:func:`nlosfw.model.split_field`) to score it
    on the held-out samples afterwards (:func:`nlosfw.model.field_metrics`). For the fit's
    report (steps, seconds, losses), create the plugin and call its ``fit`` yourself.
    """
    fitted = _host().registry.create(PluginKind.FIELD_MODEL, model, options)
    fitted.fit(field)
    return fitted


def predict_field(model: FieldModel, like: PhasorField) -> PhasorField:
    """The fitted ``model``'s field at the wall samples, frequencies, geometry and spectral
    weights of ``like`` (typically the full field a split came from)."""
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
    voxels = wall_voxels(field if grid is None else grid, depths)
    plugin = _host().registry.create(PluginKind.IMAGER, imager, options)
    return plugin.reconstruct(field, voxels)


def run(overrides: Sequence[str] = (), *, output_dir: str | Path | None = None,
        config_name: str = "config") -> RunOutput:
    """One run of the pipeline, exactly as ``python -m nlosfw OVERRIDES...`` runs it.

    ``overrides`` are the command line's (``["scene=letter_t", "model=interp",
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
    from nlosfw.compose import run_in_process

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


def _host() -> PluginHost:
    return load_plugins()

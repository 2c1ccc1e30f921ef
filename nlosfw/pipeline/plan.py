"""What one run will do, decided once: :func:`make_plan` turns a resolved configuration (the
plain mapping Hydra composed, or ``nlosfw.run``'s) into a frozen :class:`RunPlan`.

It is the only validator of a configuration and the only reader of its options by name:
the checks before a run are making the plan (so nothing passes them and fails later for a
reason they could have seen), and the :class:`~nlosfw.pipeline.Pipeline` runs the plan and
never reads the configuration again (it writes and hashes it). The plan holds every
decision: the settings, the plugins built and what each declares it needs, the transform
actually used (for a capture file imaged by a time-domain imager, the measured-capture
band), the depth rule (:class:`~nlosfw.pipeline.depth_plan.DepthPlan`), the capture (a
file read and preprocessed once, its format detected once; a scene), its sizes and the
memory estimate. Every mistake the configuration can hold is a one-line error here, before
the run directory is touched; the memory is checked before the capture file's data is read.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.source import FileCapture, FormatCatalogue, open_capture
from nlosfw.common.errors import ConfigError
from nlosfw.common.logs import recorded
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.evaluation.reference import memory_reason, reference_bytes, reference_reason
from nlosfw.image.choice import Pick, picked_for, picked_imager
from nlosfw.image.depths import MAX_AUTOMATIC_PLANES
from nlosfw.image.interface import Imager, ImagerNeeds
from nlosfw.image.transient import full_band_frequencies, measured_band_frequencies
from nlosfw.model.interface import ModelNeeds
from nlosfw.pipeline.budget import RunCounts, array_parts, check_memory
from nlosfw.pipeline.depth_plan import DepthPlan
from nlosfw.pipeline.plan_capture import (
    Takers,
    TrainingSplit,
    capture_shape,
    check_capture_kind,
    check_file_counts,
    check_scene_counts,
    check_scene_preprocessing,
    header_shape,
)
from nlosfw.pipeline.plan_plugins import (
    PlainConfig,
    Planned,
    PlannedModel,
    checked_plugins,
    imager_needs,
    planned_models,
    plugin_options,
    plugin_version,
)
from nlosfw.pipeline.settings import NO_MODEL, RunSettings, SplitSettings, StopAfter, run_settings
from nlosfw.plugins import PluginHost, PluginKind
from nlosfw.simulate.geometry import validate_scene
from nlosfw.simulate.interface import Simulator
from nlosfw.simulate.scene import NoiseModel, Scene, scene_from_config
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.interface import PhasorTransform

__all__ = ["PlainConfig", "Planned", "PlannedModel", "RunPlan", "make_plan",
           "plugin_options", "plugin_version"]

#: The plugins that take the capture as it is (a file's): they must take its kind.
_TAKE_THE_CAPTURE = (PluginKind.PHASOR_TRANSFORM, PluginKind.IMAGER)


@dataclass(frozen=True, eq=False)
class RunPlan:
    """A run's decisions, checked and built (see the module's documentation)."""

    config: PlainConfig
    """The resolved configuration (written to config.yaml, hashed for resumed sweeps)."""
    settings: RunSettings
    transform: Planned[PhasorTransform]
    """The transform the run uses (the configured one, or its measured-capture band)."""
    imager: Planned[Imager]
    models: tuple[PlannedModel, ...]
    """The selected model, the interp baseline and every ``compare`` model, in that order."""
    formats: FormatCatalogue
    """The installed capture formats (a background file)."""
    depths: DepthPlan
    """The one rule of the run's depth range and planes."""
    shape: PlanShape
    """The run's sizes."""
    memory: MemoryEstimate
    """The memory the run needs (the program itself not counted)."""
    imager_needs: ImagerNeeds = ImagerNeeds()
    simulator: Planned[Simulator] | None = None
    """The simulator of a simulated capture (None for a capture file)."""
    scene: Scene | None = None
    """The scene of a simulated capture (None for a capture file)."""
    capture: FileCapture | None = None
    """The capture file, read and preprocessed (None for a simulated capture)."""
    format_versions: Mapping[str, str] | None = None
    """``distribution==version`` of each capture format, by name."""
    transform_note: str = ""
    """Why the transform used is not the configured one ('' when it is), for the log."""
    imager_note: str = ""
    """Which imager ``reconstruction.pick_imager`` picked and why ('' when it is off)."""
    picked: PlainConfig | None = None
    """The configuration's nodes the pick replaces (``imager``, ``reconstruction``) in what
    the run says it used (:meth:`used_config`); None when nothing was picked."""
    read_log: tuple[logging.LogRecord, ...] = ()
    """What reading the capture file logged (said again in the run's log)."""

    @property
    def choices(self) -> dict[str, str]:
        """The scene and plugin names the run uses, by group (:meth:`used_config`'s)."""
        return choices(self.used_config())

    def selected(self, group: str) -> str | None:
        """The plugin or scene name the configuration selects in ``group`` (None: none)."""
        return self.choices.get(group)

    @property
    def images_only(self) -> bool:
        """``model=none``: the run images the capture alone (no split, no field model)."""
        return self.selected("model") == NO_MODEL

    @property
    def needs(self) -> ModelNeeds:
        """What the run's field models need of it, together."""
        return _models_needs(self.models)

    def used_config(self) -> PlainConfig:
        """The configuration without what the run does not use: a run from a file has no
        scene and no simulator (their defaults would mislabel it)."""
        config = {**self.config, **(self.picked or {})}
        if self.settings.capture.path is None:
            return config
        return {k: v for k, v in config.items() if k not in ("scene", "simulator")}


def _models_needs(models: Iterable[PlannedModel]) -> ModelNeeds:
    """What ``models`` need of a run, together."""
    needs = ModelNeeds()
    for planned in models:
        needs = needs | planned.needs
    return needs


def make_plan(config: PlainConfig, host: PluginHost) -> RunPlan:
    """The plan of the run ``config`` describes, its plugins built from ``host``; a one-line
    error for anything the configuration, its plugins or its capture cannot do."""
    settings = run_settings(config)
    check_model_choice(config, settings)
    chosen = checked_plugins(config, host)
    registry = host.registry

    def planned(kind: PluginKind) -> Planned[Any]:
        name, options = chosen[kind.value]
        return Planned(name, registry.create(kind, name, options),
                       plugin_version(host, kind, name))

    transform: Planned[PhasorTransform] = planned(PluginKind.PHASOR_TRANSFORM)
    imager: Planned[Imager] = planned(PluginKind.IMAGER)
    needs = imager_needs(imager.plugin)
    check_reference_choice(settings, imager.name, needs.time_domain)
    models = planned_models(config, settings, host,
                            chosen.get(PluginKind.FIELD_MODEL.value, ("", None))[1])
    takers: Takers = {group: (chosen[group][0], registry.get(group, chosen[group][0])
                              .capabilities) for group in (PluginKind.SIMULATOR.value,
                                                           *(k.value for k in _TAKE_THE_CAPTURE))}
    base = _Base(config=config, settings=settings, transform=transform, imager=imager,
                 models=models, needs=needs, takers=takers, formats=host.capture_formats(),
                 training=TrainingSplit.of(settings.split), host=host)
    if settings.capture.path is None:
        plan = _scene_plan(base, planned(PluginKind.SIMULATOR))
    else:
        plan = _file_plan(base)
    versions = {name: plugin_version(host, PluginKind.CAPTURE_FORMAT, name)
                for name in registry.names(PluginKind.CAPTURE_FORMAT)}
    return dataclasses.replace(plan, format_versions=versions)


@dataclass(frozen=True, eq=False)
class _Base:
    """What :func:`make_plan` decides before the capture."""

    config: PlainConfig
    settings: RunSettings
    transform: Planned[PhasorTransform]
    imager: Planned[Imager]
    models: tuple[PlannedModel, ...]
    needs: ImagerNeeds
    takers: Takers
    formats: FormatCatalogue
    training: TrainingSplit
    host: PluginHost
    imager_note: str = ""
    picked: PlainConfig | None = None

    def picking(self, pick: Pick) -> _Base:
        """With ``reconstruction.pick_imager``: this base imaging with ``pick``'s imager at
        its defaults (in the configuration too), making no reference picture unless
        ``reconstruction.histogram_reference`` is true; else this base as it is."""
        reconstruction = self.settings.reconstruction
        if not reconstruction.pick_imager:
            return self
        kind = PluginKind.IMAGER
        spec = self.host.registry.get(kind, pick.name)
        imager: Planned[Imager] = Planned(
            pick.name, self.host.registry.create(PluginKind.IMAGER, pick.name),
            plugin_version(self.host, kind, pick.name))
        reference = bool(reconstruction.histogram_reference)
        settings = dataclasses.replace(self.settings, reconstruction=dataclasses.replace(
            reconstruction, histogram_reference=reference))
        options = msgspec.to_builtins(imager.plugin.config)
        node = self.config.get("reconstruction")
        picked = {"imager": {"name": pick.name, **options},
                  "reconstruction": {**(dict(node) if isinstance(node, Mapping) else {}),
                                     "histogram_reference": reference}}
        needs = imager_needs(imager.plugin)
        check_reference_choice(settings, pick.name, needs.time_domain)
        return dataclasses.replace(
            self, picked=picked, settings=settings, imager=imager, needs=needs,
            takers={**self.takers, kind.value: (pick.name, spec.capabilities)},
            imager_note=pick.why)

    @property
    def model_needs(self) -> ModelNeeds:
        return _models_needs(self.models)

    def estimate(self, shape: PlanShape, counts: RunCounts,
                 reference: PlanShape | None = None) -> MemoryEstimate:
        """The engine's arrays, the imager's and every model's own estimate, checked against
        the memory available (a one-line ConfigError when it does not fit). ``reference``:
        the shape of the reference picture's field (the histograms at native bins) when the
        run makes one: the imager images it after the run's fields, so the larger of its
        two estimates counts."""
        estimate = array_parts(shape, counts) + self._imaging(shape, counts, reference)
        for planned in self.models:
            own = type(planned.model).estimate_memory(planned.model.config, shape)
            estimate = estimate + labelled(own, planned.option, planned.name)
        check_memory(estimate, self.settings.limits.allow_large)
        return estimate

    def _imaging(self, shape: PlanShape, counts: RunCounts,
                 reference: PlanShape | None) -> MemoryEstimate:
        """The imager's own estimate for the run's fields, or for the reference picture's
        (with its field) when that is larger."""
        imager = self.imager.plugin
        own = type(imager).estimate_memory(imager.config, shape, counts.depth_planes)
        if reference is not None:
            field = MemoryPart("the reference picture's field",
                               f"{reference.frequencies} frequencies (native bins) × "
                               f"{reference.sensors * reference.lasers} samples",
                               16.0 * reference.samples)
            native = type(imager).estimate_memory(imager.config, reference,
                                                  counts.depth_planes) + MemoryEstimate((field,))
            if native.total > own.total:
                return labelled(native, "imager", f"{self.imager.name}, the reference picture")
        return labelled(own, "imager", self.imager.name)

    def counts(self, depth_planes: int, why: str, noisy: bool = False,
               read: bool = False) -> RunCounts:
        return RunCounts(models=len(self.models), noisy=noisy, read=read,
                         thinned=self.settings.split.count_splitting, depth_planes=depth_planes,
                         single_frequency_images=(
                             self.settings.reconstruction.single_frequency_images),
                         why=why)

    def plan(self, shape: PlanShape, memory: MemoryEstimate, **more: object) -> RunPlan:
        return RunPlan(config=self.config, settings=self.settings, transform=self.transform,
                       imager=self.imager, models=self.models, formats=self.formats,
                       depths=DepthPlan.of(self.settings.reconstruction), shape=shape,
                       memory=memory,
                       imager_needs=self.needs, imager_note=self.imager_note,
                       picked=self.picked, **more)  # type: ignore[arg-type]


def _given_planes(settings: RunSettings) -> int | None:
    reconstruction = settings.reconstruction
    return len(reconstruction.depths) or reconstruction.n_depths


def _scene_plan(base: _Base, simulator: Planned[Simulator]) -> RunPlan:
    """The plan of a simulated capture: sized from the scene before anything is allocated,
    then the scene, the simulator and the preprocessing checked on a stand-in capture."""
    scene = scene_from_config(base.config.get("scene"))
    base = base.picking(picked_imager(CaptureKind(str(scene.capture.type)), True))
    settings = base.settings
    nx, ny = (int(n) for n in scene.wall.resolution)
    bins = int(scene.time.bins)
    spacing = min(float(s) / max(int(r), 1) for s, r in
                  zip(scene.wall.size, scene.wall.resolution, strict=False))
    planes = _given_planes(settings) or _scene_planes(bins * float(scene.time.bin_width),
                                                      spacing)
    counts = base.counts(planes, f"scene.wall.resolution {[nx, ny]} × scene.time.bins {bins}",
                         noisy=scene.noise.model != NoiseModel.none)
    frequencies = base.transform.plugin.frequency_count(bins)
    sized = base.training.sized(PlanShape(
        bins=bins, sensors=nx * ny, grid=(ny, nx), spacing=spacing,
        confocal=str(scene.capture.type) == "confocal", frequencies=frequencies,
        depth_range=DepthPlan.of(settings.reconstruction).given))
    base.estimate(sized, counts)                   # before anything sized by it is allocated
    scene = validate_scene(scene).scene
    check_scene_counts(scene, settings.split.count_splitting,
                       settings.capture.pileup_pulses is not None, base.model_needs)
    simulator.plugin.check(scene)
    layout = check_scene_preprocessing(scene, settings.capture.options, base.formats)
    check_capture_kind(layout, base.takers, f"scene {scene.name}'s capture "
                                            f"(scene.capture.type={scene.capture.type})")
    band = capture_shape(layout, base.transform.plugin, base.training, sized.depth_range)
    shape = dataclasses.replace(band, bins=bins, sensors=nx * ny, lasers=1)
    return base.plan(shape, base.estimate(shape, counts), simulator=simulator, scene=scene)


def _scene_planes(window: float, spacing: float) -> int:
    """At most the planes the automatic rule chooses over a scene's time window: at least
    half a wall spacing apart over half the window, at most :data:`MAX_AUTOMATIC_PLANES`."""
    ratio = window / spacing if spacing > 0 else math.inf
    if not math.isfinite(ratio):  # a non-finite size is refused by the scene's own checks
        return MAX_AUTOMATIC_PLANES
    return max(2, min(MAX_AUTOMATIC_PLANES, math.ceil(ratio) + 1))


def _file_plan(base: _Base) -> RunPlan:
    """The plan of a capture file: opened once, its format detected once, sized from its
    header and the memory checked before its data is read, then read and preprocessed once
    and checked."""
    settings = base.settings
    planes = _given_planes(settings) or MAX_AUTOMATIC_PLANES
    with recorded() as said, open_capture(settings.capture, base.formats) as file:
        header = file.transient_shape()
        if header is not None:
            bins, sensors, lasers = header
            why = f"capture.path's transient of {bins} time bins × {sensors * lasers} samples"
            base.estimate(header_shape(header, base.transform.plugin, base.training),
                          base.counts(planes, why, read=True))
        loaded = file.load()
    capture = loaded.prepared.capture
    base = base.picking(picked_for(capture))
    check_capture_kind(capture, {k: v for k, v in base.takers.items()
                                 if k != PluginKind.SIMULATOR.value}, str(loaded.path))
    check_file_counts(loaded, settings.split.count_splitting,
                      settings.split.count_splitting_seed,
                      base.model_needs, (base.transform.name, base.transform.plugin))
    transform, note = _measured_band(base, capture)
    depths = DepthPlan.of(settings.reconstruction)
    depth_range = depths.span(capture)
    shape = capture_shape(capture, transform.plugin, base.training, depth_range)
    why = (f"capture.path's transient of {shape.bins} time bins × "
           f"{shape.sensors * shape.lasers} samples")
    planes = depths.count(depth_range, shape.f_max, capture.kind)   # known once it is read
    memory = base.estimate(shape, base.counts(planes, why, read=True),
                           _reference_shape(base, capture, shape))
    return dataclasses.replace(base.plan(shape, memory, capture=loaded), transform=transform,
                               transform_note=note, read_log=tuple(said))


def _reference_shape(base: _Base, capture: Capture, shape: PlanShape) -> PlanShape | None:
    """The shape of the reference picture's field (every DFT bin of the histograms) when the
    run will make one (:func:`~nlosfw.evaluation.reference.reference_reason`, and the memory
    it needs available, :func:`~nlosfw.evaluation.reference.memory_reason`: else the run
    skips it), else None."""
    settings = base.settings
    reason = reference_reason(settings.reconstruction.histogram_reference,
                              base.imager.name, base.needs.time_domain, True, capture)
    if reason is not None or shape.depth_range is None:
        return None
    needed = reference_bytes(capture, np.asarray(shape.depth_range, dtype=float),
                             base.imager.plugin.config)
    if memory_reason(needed, settings.limits.allow_large) is not None:
        return None
    freqs = full_band_frequencies(capture.n_bins, capture.delta_t)
    return dataclasses.replace(shape, frequencies=int(freqs.size), f_min=float(freqs[0]),
                               f_max=float(freqs[-1]))


def _measured_band(base: _Base, capture: Capture) -> tuple[Planned[PhasorTransform], str]:
    """The run's transform for a capture file: for a time-domain imager (lct, fk, fbp) and
    the ``fft`` transform's default band, the measured-capture band instead
    (:func:`nlosfw.image.transient.measured_band_frequencies`; ``transform.f_min``,
    ``f_max`` or ``frequencies`` choose another), with the line the log says about it."""
    planned = base.transform
    plugin = planned.plugin
    if (not base.needs.time_domain or not isinstance(plugin, FFTTransform)
            or plugin.config.frequencies or plugin.config.f_min is not None
            or plugin.config.f_max is not None):
        return planned, ""
    freqs = measured_band_frequencies(capture.n_bins, capture.delta_t)
    note = (f"a measured capture imaged by {base.imager.name}: the band "
            f"{freqs[0]:.3g}-{freqs[-1]:.3g} cycles/m ({freqs.size} DFT bins); "
            "transform.f_min/f_max choose another")
    used = FFTTransform(dataclasses.replace(plugin.config,
                                            frequencies=tuple(float(f) for f in freqs)))
    return Planned(planned.name, used, planned.version), note


def labelled(estimate: MemoryEstimate, option: str, name: str) -> MemoryEstimate:
    """A model's estimate with each part's why naming the model as the configuration does
    (``model (siren_torch): ...``, ``compare.pe (pe_torch): ...``; a part shared with other
    models, a runtime, is left as it is)."""
    return MemoryEstimate(tuple(part if part.once else dataclasses.replace(
        part, why=f"{option} ({name}): {part.why}") for part in estimate.parts))


def choices(config: PlainConfig) -> dict[str, str]:
    """The scene and plugin names ``config`` selects, by group."""
    found = {}
    for group in ("scene", "simulator", "transform", "model", "imager"):
        node = config.get(group)
        name = node.get("name") if isinstance(node, Mapping) else None
        if name is not None:
            found[group] = str(name)
    return found


def check_model_choice(config: PlainConfig, settings: RunSettings) -> None:
    """A one-line ConfigError for options that ``model=none`` (no field model: the capture
    is imaged alone) cannot honour: a split, ``compare`` models, stopping after fit or
    predict."""
    node = config.get("model")
    if not isinstance(node, Mapping) or node.get("name") != NO_MODEL:
        return
    if settings.compare:
        raise ConfigError("compare", "model=none fits no field model, so there is nothing to "
                          "compare; select a model (model=interp) or leave compare empty")
    if settings.split != SplitSettings():
        raise ConfigError("split", "model=none images the whole capture and splits nothing; "
                          "leave the split options at their defaults or select a model "
                          "(model=interp)")
    if settings.stop_after in (StopAfter.fit, StopAfter.predict):
        raise ConfigError("stop_after", f"model=none fits and predicts nothing; stop after "
                          f"capture, transform or reconstruct, not {settings.stop_after}")


def check_reference_choice(settings: RunSettings, imager: str, time_domain: bool) -> None:
    """A one-line ConfigError for ``reconstruction.histogram_reference=true`` with an imager
    that images a band (not ``time_domain``, as lct, fk and fbp are)."""
    if settings.reconstruction.histogram_reference and not time_domain:
        raise ConfigError("reconstruction.histogram_reference", f"true images the histograms "
                          f"with a time-domain imager (lct, fk or fbp), and imager {imager} "
                          "images a band of frequencies; select one or leave it null")

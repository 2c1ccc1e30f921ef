"""The end-to-end run: capture -> transform -> split -> fit -> predict -> reconstruct -> report.

The fields imaged side by side, all with the same imager on the same voxels: the
true full-resolution field (the reference), the raw samples the models train on
(a sub-grid, or scattered points), the ``interp`` baseline's prediction, and the
prediction of every field model of the run (``model`` and each ``compare`` label);
every reconstruction is scored against the one from the true field. The stages hand
each other the typed results of :mod:`nlosfw.app.results` and record their numbers in
the run's :class:`~nlosfw.app.metrics.RunMetrics`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from rich.progress import Progress

from nlosfw.app import lifecycle
from nlosfw.app.budget import check_memory, memory_summary
from nlosfw.app.cache import Cache, cache_key, file_digest
from nlosfw.app.console import app_console, progress_bar, step
from nlosfw.app.interrupts import as_interruption, signals_raise
from nlosfw.app.measure import (
    capture_metrics,
    denoising_metrics,
    fit_metrics,
    reconstruction_metrics,
    split_metrics,
    transform_metrics,
    truth_depth_image,
)
from nlosfw.app.metrics import FieldMetrics, RunError, RunInfo, RunMetrics, SplitErrors, Status
from nlosfw.app.results import (
    CaptureResult,
    FitResult,
    FittedModel,
    FrequencySplit,
    ImagedFields,
    Reconstructions,
    RunResults,
    SingleFrequencyImages,
    StageResults,
    TransformResult,
)
from nlosfw.app.run_dir import PLANNED_NAMES, RunContext, format_size
from nlosfw.app.settings import Artefact, RunSettings, run_settings
from nlosfw.capture.data import Capture
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import yaml_safe
from nlosfw.common.config import config_to_dict
from nlosfw.common.errors import ConfigError, NlosfwError, one_line
from nlosfw.common.progress import accepts_progress
from nlosfw.common.version import __version__
from nlosfw.image.depths import automatic_depths, depth_span
from nlosfw.image.reconstruction import Reconstruction, wall_voxels
from nlosfw.image.reconstruction_io import write_reconstruction
from nlosfw.model.interface import FieldModel, FitReport, TrainingStep
from nlosfw.model.protocol import FieldSplit
from nlosfw.plugins import PluginHost, load_plugins
from nlosfw.transform import frequencies as frequencies_module
from nlosfw.transform.field import PhasorField
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field
from nlosfw.transform.frequencies import warn_aliasing

log = logging.getLogger(__name__)


def run_pipeline(cfg: Any) -> float | None:
    """Hydra task: run the pipeline in Hydra's output directory; returns the held-out NMSE (dB).

    A job of a multirun may resume its sweep directory (see :mod:`nlosfw.app.lifecycle`).
    """
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    hydra = HydraConfig.get()
    run_dir = Path(hydra.runtime.output_dir)
    plain = cast("dict[str, Any]", OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))
    return Pipeline(run_dir, plain, load_plugins(),
                    resume=hydra.mode == RunMode.MULTIRUN).run()


class Pipeline:
    """One run of every stage up to ``stop_after``, writing into ``run_dir``.

    ``resume``: the run is a job of a sweep that may be resumed in its directory (a
    finished job of the same configuration is then skipped).
    """

    def __init__(self, run_dir: Path, config: dict[str, Any], host: PluginHost,
                 resume: bool = False) -> None:
        self.config = config
        self.settings: RunSettings = run_settings(config)
        self.host = host
        self.run_dir = Path(run_dir)
        self.resume = resume
        self.console = app_console()
        self.ctx = RunContext(self.run_dir, host, self._run_info(),
                              keep=frozenset(self.settings.output.keep))
        self.cache = Cache(self.settings.cache.dir, self.settings.cache.enabled,
                           max_gb=self.settings.cache.max_gb)
        self.stage_results = StageResults()
        """What the stages produced so far (all of it once :meth:`run` has returned)."""

    @property
    def metrics(self) -> RunMetrics:
        """The run's metrics so far (all of them once :meth:`run` has returned)."""
        return self.ctx.metrics

    # ------------------------------------------------------------------ driver
    def run(self) -> float | None:
        """Run the stages; returns the held-out NMSE (dB) of the model, None when stopped
        early or skipped. Everything that can be checked is checked before the first byte
        is written; a failed or interrupted (SIGINT, SIGTERM) run leaves metrics.json
        saying where and why, and no temporary file."""
        from nlosfw.app.capture_source import file_transient_shape

        def file_shape(path: Path) -> tuple[int, int, int] | None:
            return file_transient_shape(path, self.settings.capture.format, self.host)

        check_memory(self.config, file_shape=file_shape)
        log.info(memory_summary(self.config, file_shape))
        with signals_raise(), lifecycle.held(
                self.run_dir, self.config, PLANNED_NAMES, overwrite=self.settings.output.overwrite,
                resume=self.resume) as hold:
            if hold is None:
                self.console.print(f"[yellow]skipping[/]: {self.run_dir} already holds a "
                                   "finished run of this configuration")
                return None
            self.ctx.hold = hold
            return self._run_held()

    def _run_held(self) -> float | None:
        from nlosfw.app.overview import overview_lines

        shown = self._used_config()
        self.console.print(f"[bold]nlosfw run[/] → {self.run_dir}", highlight=False)
        for line in overview_lines(shown, self.host, self.settings):
            self.console.print(line, highlight=False)
        self.console.print("  full configuration: config.yaml and .hydra/ in the run directory",
                           highlight=False)
        try:
            self.host.hook.on_run_start(run_dir=str(self.run_dir), config=self.config)
            self.ctx.write_text("config", yaml_safe.dump(shown))
            objective = self._stages()
        except BaseException as err:  # any failure, ours or a bug: record it, then re-raise
            self._record_end(err)
            raise
        status: Literal["completed", "stopped"] = (
            "completed" if self.settings.stop_after is None else "stopped")
        if status == "stopped":
            run = replace(self.metrics.run, stopped_after=self.settings.last_stage)
            self.ctx.metrics = replace(self.metrics, run=run)
        self.ctx.finish(status)
        self._write_html_report()
        self.host.hook.on_run_end(run_dir=str(self.run_dir), metrics=self.metrics.to_json(),
                                  status=status)
        from nlosfw.app.summary import summary_table

        self.console.print(summary_table(self.metrics))
        self.console.print(f"[bold green]done[/] ({status}): {self.run_dir}, "
                           f"{format_size(self.ctx.size())} {self._kept_text()}", highlight=False)
        return objective

    def _write_html_report(self) -> None:
        """report.html: the run's figures, metrics, timings and configuration in one page."""
        from nlosfw.app.html_report import run_report

        overrides = []
        path = self.run_dir / ".hydra" / "overrides.yaml"
        if path.is_file():
            overrides = [str(o) for o in yaml_safe.load(path.read_text(encoding="utf-8")) or []]
        self.ctx.write_text("report.html", run_report(self.run_dir, self.metrics, self.config,
                                                      overrides), kind="report")

    def _kept_text(self) -> str:
        """Which large files the run kept and which output.keep left out."""
        kept = ", ".join(str(a) for a in self.settings.output.keep) or "none"
        left = ", ".join(str(a) for a in Artefact if a not in self.settings.output.keep)
        return (f"(large files kept: {kept}" + (f"; not written: {left}, see output.keep)"
                                                 if left else ")"))

    def _used_config(self) -> dict[str, Any]:
        """The config without what the run does not use: a run from a file has no scene and
        no simulator (their defaults would mislabel it)."""
        if self.settings.capture.path is None:
            return self.config
        return {k: v for k, v in self.config.items() if k not in ("scene", "simulator")}

    def _record_end(self, err: BaseException) -> None:
        """metrics.json with status failed or interrupted, the stage and the one-line reason,
        and the on_run_end hook, never masking the error."""
        interruption = as_interruption(err)
        status: Status = "failed" if interruption is None else "interrupted"
        if interruption is not None:
            error = RunError(stage=self.ctx.stage_reached, message=str(interruption),
                             signal=interruption.signal_name)
        else:
            message = (one_line(err, whole=True) if isinstance(err, NlosfwError)
                       else f"{type(err).__name__}: {one_line(err, whole=True)}")
            error = RunError(stage=self.ctx.stage_reached, message=message)
        try:
            self.ctx.finish(status, error)
            self.host.hook.on_run_end(run_dir=str(self.run_dir), metrics=self.metrics.to_json(),
                                      status=status)
        except Exception as failure:  # the original failure is what the user must see
            log.error("could not record the %s run in %s: %s", status, self.run_dir,
                      one_line(failure))

    def _stages(self) -> float | None:
        s = self.settings
        with self.ctx.stage("capture"):
            capture = self.capture()
        self.stage_results = replace(self.stage_results, capture=capture)
        if not s.runs("transform"):
            return None
        with self.ctx.stage("transform"):
            transformed = self.transform(capture)
        self.stage_results = replace(self.stage_results, transform=transformed)
        if not s.runs("fit"):
            return None
        with self.ctx.stage("fit"):
            fitted = self.fit(transformed.field)
        self.stage_results = replace(self.stage_results, fit=fitted)
        if not s.runs("predict"):
            return None
        with self.ctx.stage("predict"):
            fields = self.predict(transformed, fitted)
        self.stage_results = replace(self.stage_results, fields=fields)
        if not s.runs("reconstruct"):
            return None
        with self.ctx.stage("reconstruct"):
            recons = self.reconstruct(capture.capture, fitted.split, fields)
        self.stage_results = replace(self.stage_results, reconstructions=recons)
        if s.runs("report"):
            with self.ctx.stage("report"):
                self.report(RunResults(capture=capture, transform=transformed, fit=fitted,
                                       fields=fields, reconstructions=recons))
        entry = self.metrics.field_entry("model") or self.metrics.field_entry("interp")
        assert entry is not None and entry.splits is not None  # both set by fit and predict
        return entry.splits.heldout_pixels.nmse_db

    # ------------------------------------------------------------------ stages
    def capture(self) -> CaptureResult:
        """Read ``capture.path`` (format forced or detected) or simulate the scene (cached),
        preprocess it; write capture.hdf5."""
        source = self.settings.capture
        if source.path is not None:
            result = self._file_capture()
        else:
            result = self._preprocessed(self._simulated_capture())
        self.ctx.write("capture", lambda p: write_capture(
            p, result.capture, compression=self.settings.output.compression),
            keep_as=Artefact.capture)
        self.ctx.metrics = replace(self.metrics, capture=capture_metrics(result))
        return result

    def transform(self, capture: CaptureResult) -> TransformResult:
        """The capture's phasor field (cached), and the noise-free capture's; write it."""
        name, options = self._plugin_options("transform")
        transform = self.host.registry.create("transform", name, options)

        canonical = config_to_dict(transform.config)

        def cached_field(source: Capture, source_key: str) -> tuple[PhasorField, bool]:
            key = cache_key({"capture": source_key, "transform": name, "options": canonical,
                             "plugin": self._plugin_version("transform", name)})
            return self.cache.get_or_compute(
                "fields", key, lambda: transform.transform(source),
                lambda p, f: write_phasor_field(p, f), read_phasor_field)

        with step(f"phasor field ({name})", self.console) as set_info, \
                _once_per_message(logging.getLogger(frequencies_module.__name__)):
            field, hit = cached_field(capture.capture, capture.key)
            clean = None
            if capture.clean is not None and capture.clean_key is not None:
                clean = cached_field(capture.clean, capture.clean_key)[0]
            set_info(f"{field.n_frequencies} frequencies" + (" (cached)" if hit else ""))
            # also from a cached field: the band's aliasing warning once per run
            band = field.metadata.get("band") or {}
            if band.get("aliases") and band.get("grid_spacing") is not None:
                warn_aliasing(float(field.frequencies.max()), float(band["grid_spacing"]),
                              field.geometry.kind, str(band.get("option", "transform")))
        self.ctx.write("phasor_field", lambda p: write_phasor_field(p, field),
                       keep_as=Artefact.phasor_field)
        result = TransformResult(field=field, cache_hit=hit, clean=clean)
        self.ctx.metrics = replace(self.metrics, transform=transform_metrics(name, result))
        return result

    def fit(self, field: PhasorField) -> FitResult:
        """Split the field, fit the selected model and the interp baseline."""
        from nlosfw.model.protocol import split_field

        s = self.settings.split
        split = split_field(field, s.sampling, spectral=s.spectral,
                            spectral_fraction=s.spectral_fraction)
        name, options = self._plugin_options("model")
        self.ctx.metrics = replace(self.metrics, split=split_metrics(split), field={})
        models = []
        for source, (plugin, opts) in self._field_models(name, options).items():
            model = self.host.registry.create("model", plugin, opts)
            report = self._fit_with_progress(source, plugin, model, split.train_field)
            fitted = FittedModel(source=source, plugin=plugin, model=model, report=report)
            models.append(fitted)
            self._record_field(source, fit_metrics(fitted, split))
            if source == "model":
                self.ctx.write("field_model", model.save, kind="field_model",
                               keep_as=Artefact.model)
        return FitResult(split=split, models=tuple(models))

    def predict(self, transformed: TransformResult, fitted: FitResult) -> ImagedFields:
        """The fields to image: true, raw (training samples, all frequencies), every model's."""
        field, split = transformed.field, fitted.split
        predicted = {}
        with progress_bar(self.console) as progress:
            task = progress.add_task("predict", total=len(fitted.models), info="")
            for fm in fitted.models:
                progress.update(task, info=f"{fm.source} ({fm.plugin})")
                start = time.perf_counter()
                predicted[fm.source] = fm.model.predict_field(
                    field.wall_xyz, field.frequencies, field.geometry, field.weights,
                    metadata={"source": fm.source})
                seconds = time.perf_counter() - start
                self._record_prediction(fm.source, transformed, predicted[fm.source], split,
                                        seconds)
                progress.update(task, advance=1)
            progress.update(task, info=", ".join(fm.plugin for fm in fitted.models))
        fields = ImagedFields(true=field, raw=split.raw_field(field), predicted=predicted)
        for source, f in fields.items():
            self.ctx.write(f"fields/{source}.hdf5", partial(write_phasor_field, field=f),
                           kind="phasor_field", keep_as=Artefact.fields)
        return fields

    def _record_prediction(self, source: str, transformed: TransformResult,
                           prediction: PhasorField, split: FieldSplit, seconds: float) -> None:
        """The field errors (and denoising gains) of one model's prediction."""
        from nlosfw.model.protocol import field_metrics

        field = transformed.field
        denoising = (None if transformed.clean is None
                     else denoising_metrics(transformed.clean, field, prediction))
        entry = self.metrics.field_entry(source)
        assert entry is not None  # recorded by fit
        self._record_field(source, replace(
            entry, predict_seconds=round(seconds, 4),
            splits=SplitErrors.of(field_metrics(field, prediction, split)),
            denoising=denoising))

    def reconstruct(self, capture: Capture, split: FieldSplit,
                    fields: ImagedFields) -> Reconstructions:
        """Image every field on the same voxels, then each from single frequencies alone."""
        name, options = self._plugin_options("imager")
        imager = self.host.registry.create("imager", name, options)
        voxels = self._voxels(capture, fields.true)
        # as in the thesis figures: images from one frequency at a time, too
        chosen = chosen_frequencies(split, self.settings.reconstruction.single_frequency_images)
        sources = fields.by_source()
        log.info("%d reconstructions with %s: %d fields (%s) from all %d frequencies%s",
                 len(sources) * (1 + len(chosen)), name, len(sources), ", ".join(sources),
                 fields.true.n_frequencies,
                 "".join(f" and from f = {fields.true.frequencies[i]:.4g} /m ({label})"
                         for label, i in chosen.items()))
        by_source: dict[str, Reconstruction] = {}
        seconds: dict[str, float] = {}
        with progress_bar(self.console) as progress:
            for source, field in fields.items():
                start = time.perf_counter()
                by_source[source] = self._image(imager, field, voxels, progress,
                                                f"image {source}")
                seconds[source] = round(time.perf_counter() - start, 4)
            singles = self._single_frequency_images(imager, fields, voxels, chosen, progress)
        for source, recon in by_source.items():
            self.ctx.write(f"reconstructions/{source}.hdf5",
                           partial(write_reconstruction, recon=recon),
                           kind="reconstruction", keep_as=Artefact.reconstructions)
        recons = Reconstructions(voxels=voxels, by_source=by_source, seconds=seconds,
                                 single_frequency=tuple(singles))
        truth = truth_depth_image(capture)
        self.ctx.metrics = replace(self.metrics,
                                   reconstruction=reconstruction_metrics(name, recons, truth))
        return recons

    def _single_frequency_images(self, imager: Any, fields: ImagedFields, voxels: np.ndarray,
                                 chosen: dict[FrequencySplit, int],
                                 progress: Progress) -> list[SingleFrequencyImages]:
        """Every field imaged from each chosen frequency alone, with a progress bar."""
        if not chosen:
            return []
        sources = fields.by_source()
        task = progress.add_task("single-frequency images", total=len(chosen) * len(sources),
                                 info="")
        singles = []
        for label, index in chosen.items():
            images = {}
            for source, field in sources.items():
                progress.update(task, info=f"{source} at {label}")
                images[source] = imager.reconstruct(field.select(frequency_index=[index]),
                                                    voxels)
                progress.update(task, advance=1)
            singles.append(SingleFrequencyImages(
                index=index, frequency=float(fields.true.frequencies[index]), split=label,
                by_source=images))
        progress.update(task, info=", ".join(f"f = {s.frequency:.4g} /m ({s.split})"
                                             for s in singles))
        return singles

    def report(self, results: RunResults) -> None:
        """The thesis comparison table (for thesis presets) and the figures."""
        if self.settings.thesis:
            from nlosfw.app.records import RunRecord
            from nlosfw.app.thesis import thesis_comparison

            record = RunRecord(name=self.run_dir.name, metrics=self.metrics,
                               thesis=self.settings.thesis)
            text = thesis_comparison([record])
            if text:
                self.ctx.write_text("thesis_comparison.md", text, kind="report")
        if self.settings.figures.enabled:
            from nlosfw.app.figures import write_figures

            scores = self.metrics.reconstruction
            assert scores is not None  # recorded by reconstruct
            with step("figures", self.console):
                write_figures(self.ctx, results, scores, self.settings.figures.dpi)

    # ------------------------------------------------------------------ helpers
    def _simulated_capture(self) -> CaptureResult:
        """The scene's capture (cached), rendering the transport once even for noisy scenes.

        The noise-free capture is cached under its own key; a noisy scene's capture
        is that one with noise added (cached too), and the noise-free one is kept
        for the denoising metrics.
        """
        import dataclasses

        from nlosfw.simulate.scene import NoiseConfig, scene_from_config

        scene = scene_from_config(self.config["scene"])
        name, options = self._plugin_options("simulator")
        simulator = self.host.registry.create("simulator", name, options)
        clean_scene = dataclasses.replace(scene, noise=NoiseConfig())
        clean_key = self._capture_key(name, simulator, clean_scene)
        label = f"{scene.name} ({name})"
        with step(f"simulate {label}", self.console) as set_info:
            clean, hit = self._cached_capture(clean_key,
                                              lambda: simulator.simulate_clean(clean_scene))
            set_info("(cached)" if hit else "")
            if scene.noise == NoiseConfig():
                return CaptureResult(capture=clean, key=clean_key, source="simulated",
                                     label=label, simulator=name, cache_hit=hit)
            key = self._capture_key(name, simulator, scene)
            capture, hit = self._cached_capture(key, lambda: simulator.add_noise(clean, scene))
        return CaptureResult(capture=capture, key=key, source="simulated", label=label,
                             simulator=name, cache_hit=hit, clean=clean, clean_key=clean_key)

    def _file_capture(self) -> CaptureResult:
        """The capture of ``capture.path``, preprocessed; the run is labelled with its format."""
        from nlosfw.app.capture_source import load_file_capture

        loaded = load_file_capture(self.settings.capture, self.host)
        key = loaded.cache_key(self._plugin_version("capture_format", loaded.format))
        self.ctx.metrics = replace(self.metrics, run=replace(
            self.metrics.run, capture_format=loaded.format))
        return CaptureResult(capture=loaded.prepared.capture, key=key, source="file",
                             label=f"{loaded.path.name} ({loaded.format})",
                             path=loaded.path.resolve(), format=loaded.format,
                             steps=loaded.prepared.steps)

    def _preprocessed(self, raw: CaptureResult) -> CaptureResult:
        """A simulated capture (and its noise-free twin) with the run's preprocessing."""
        from nlosfw.app.capture_source import options_of, prepare

        options = options_of(self.settings.capture)
        prepared = prepare(raw.capture, options, frozenset(), self.host)
        if not prepared.steps:
            return raw
        key = cache_key({"capture": raw.key, **prepared.key_material})
        clean, clean_key = raw.clean, raw.clean_key
        if clean is not None:
            clean = prepare(clean, options, frozenset(), self.host).capture
            clean_key = cache_key({"capture": raw.clean_key, **prepared.key_material})
        return replace(raw, capture=prepared.capture, key=key, steps=prepared.steps,
                       clean=clean, clean_key=clean_key)

    def _cached_capture(self, key: str,
                        compute: Callable[[], Capture]) -> tuple[Capture, bool]:
        return self.cache.get_or_compute(
            "captures", key, compute, lambda p, c: write_capture(p, c, compression=1),
            read_capture)

    def _capture_key(self, name: str, simulator: Any, scene: Any) -> str:
        """Cache key of a simulated capture: the plugin and its version, its validated
        options, the validated scene with absolute mesh paths, and the mesh files' bytes."""
        from nlosfw.simulate.geometry import resolve_mesh_paths

        scene = resolve_mesh_paths(scene)
        meshes = {item.path: file_digest(Path(item.path)) for item in scene.geometry
                  if item.type == "mesh" and item.path}
        return cache_key({"simulator": name, "plugin": self._plugin_version("simulator", name),
                          "options": config_to_dict(simulator.config),
                          "scene": config_to_dict(scene), "meshes": meshes})

    def _plugin_version(self, kind: str, name: str) -> str:
        """``distribution==version`` of a plugin, so a plugin upgrade invalidates the cache."""
        from importlib.metadata import PackageNotFoundError, version

        dist = self.host.registry.get(kind, name).distribution
        try:
            return f"{dist}=={version(dist)}"
        except PackageNotFoundError:
            return f"{dist}==unknown"

    def _plugin_options(self, kind: str) -> tuple[str, dict[str, Any]]:
        node = dict(self.config.get(kind) or {})
        name = node.pop("name", None)
        if not name:
            raise ConfigError(kind, "no plugin selected")
        return str(name), node

    def _field_models(self, name: str,
                      options: dict[str, Any]) -> dict[str, tuple[str, dict[str, Any]]]:
        """The selected model, the interp baseline (unless it is the model) and ``compare``."""
        models = {"model": (name, options)} if name != "interp" else {}
        models["interp"] = (name, options) if name == "interp" else ("interp", {})
        for label, extra in self.settings.compare.items():
            rest = {k: v for k, v in extra.items() if k != "name"}
            models[label] = (str(extra["name"]), rest)
        return models

    def _record_field(self, source: str, entry: FieldMetrics) -> None:
        """Set (or replace) the metrics of field model ``source``."""
        self.ctx.metrics = replace(self.metrics, field={**(self.metrics.field or {}),
                                                        source: entry})

    def _fit_with_progress(self, source: str, plugin: str, model: FieldModel,
                           train: PhasorField) -> FitReport:
        with progress_bar(self.console) as progress:
            task = progress.add_task(f"fit {plugin}", total=None, info="")

            def on_step(step: TrainingStep) -> None:
                val = "" if step.val_loss is None else f" val {step.val_loss:.3g}"
                progress.update(task, completed=step.step, total=step.total_steps,
                                info=f"loss {step.loss:.3g}{val}")
                self.host.hook.on_training_step(source=source, model=plugin, step=step.step,
                                                total_steps=step.total_steps, loss=step.loss,
                                                val_loss=step.val_loss)

            report = model.fit(train, on_step=on_step)
            progress.update(task, completed=report.steps, total=max(report.steps, 1))
        return report

    def _image(self, imager: Any, field: PhasorField, voxels: np.ndarray,
               progress: Progress, description: str) -> Reconstruction:
        """One reconstruction with a progress bar of its blocks (when the imager reports
        them through ``on_progress``; else a bar that completes when it returns)."""
        task = progress.add_task(description, total=None, info="")
        if accepts_progress(imager.reconstruct):
            def on_progress(done: int, total: int) -> None:
                progress.update(task, completed=done, total=total)

            recon = imager.reconstruct(field, voxels, on_progress=on_progress)
        else:
            recon = imager.reconstruct(field, voxels)
        total = next(t.total for t in progress.tasks if t.id == task) or 1
        progress.update(task, completed=total, total=total)
        return recon

    def _voxels(self, capture: Capture, field: PhasorField) -> np.ndarray:
        """Planes on the wall's grid at the configured depths, or at ``n_depths`` planes, or
        (the default) at the band's depth resolution (:mod:`nlosfw.image.depths`), over
        ``depth_range`` or the depths that hold signal."""
        r = self.settings.reconstruction
        if r.depths:
            depths = np.asarray(r.depths, dtype=float)
        else:
            span = r.depth_range or depth_span(capture)
            depths = (np.linspace(span[0], span[1], r.n_depths) if r.n_depths is not None
                      else automatic_depths(span, float(field.frequencies.max()),
                                            field.geometry.kind))
        return wall_voxels(field, depths)

    def _run_info(self) -> RunInfo:
        """The run's plugins and capture: a scene and its simulator, or a file and its format
        (known once the capture stage has read it, unless ``capture.format`` forces it)."""
        def selected(group: str) -> str | None:
            name = (self.config.get(group) or {}).get("name")
            return None if name is None else str(name)

        source = self.settings.capture
        path = None if source.path is None else Path(source.path).expanduser().resolve()
        from_file = path is not None
        return RunInfo(dir=str(self.run_dir), nlosfw_version=__version__,
                       started=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                       config_hash=lifecycle.config_hash(self.config),
                       scene=None if from_file else selected("scene"),
                       simulator=None if from_file else selected("simulator"),
                       capture_file=None if path is None else str(path),
                       capture_format=source.format if from_file else None,
                       transform=selected("transform"), model=selected("model"),
                       imager=selected("imager"))


class _OnceFilter(logging.Filter):
    """Lets each distinct message through once."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if message in self.seen:
            return False
        self.seen.add(message)
        return True


@contextmanager
def _once_per_message(logger: logging.Logger) -> Iterator[None]:
    """Within the block, ``logger`` logs each distinct message once."""
    once = _OnceFilter()
    logger.addFilter(once)
    try:
        yield
    finally:
        logger.removeFilter(once)


def chosen_frequencies(split: FieldSplit, count: int) -> dict[FrequencySplit, int]:
    """Up to ``count`` frequency indices to show alone: a training one near the top of the
    band, then a held-out one (if any), by label."""
    train = np.asarray(split.train_frequencies)
    held = np.asarray(split.heldout_frequencies)
    chosen: dict[FrequencySplit, int] = {"training": int(train[int(0.75 * (train.size - 1))])}
    if held.size:
        chosen["held-out"] = int(held[held.size // 2])
    return dict(list(chosen.items())[:count])

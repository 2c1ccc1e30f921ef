"""The stages between the capture and the images: its phasor field (``transform``; with
count splitting half A's, half B's and the variance B's noise adds to it), the
split and the field models fitted to its training samples (``fit``), and the fields that
are imaged (``predict``: the true field (half B's with count splitting), the raw samples,
half A's full field as the ceiling (count splitting) and every model's prediction)."""

from __future__ import annotations

import dataclasses
import logging
import re
import time
from collections.abc import Callable
from functools import partial

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.photon_counts import count_scale, photon_counts
from nlosfw.common.config import config_to_dict
from nlosfw.common.errors import ConfigError, FitError
from nlosfw.common.hashing import cache_key
from nlosfw.evaluation.noise_floor import field_variance, kernel_power
from nlosfw.evaluation.splits import split_field
from nlosfw.model.interface import TrainingStep
from nlosfw.pipeline.context import StageContext
from nlosfw.pipeline.measure import fit_metrics, prediction_scores, split_metrics, transform_metrics
from nlosfw.pipeline.plan import PlannedModel
from nlosfw.pipeline.results import (
    CaptureResult,
    FitResult,
    FittedModel,
    ImagedFields,
    StageResults,
    TransformResult,
    required,
)
from nlosfw.pipeline.settings import Artefact
from nlosfw.transform.common import histogram_2d, to_field_layout
from nlosfw.transform.counts import check_counts_times
from nlosfw.transform.field import PhasorField, PhotonCounts
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field
from nlosfw.transform.frequencies import band_warning
from nlosfw.transform.interface import PhasorTransform

log = logging.getLogger(__name__)

def transform_stage(run: StageContext, done: StageResults) -> TransformResult:
    """The capture's phasor field (cached), and the noise-free capture's; write it. The
    transform is the plan's (for a capture file imaged by a time-domain imager, the
    measured-capture band); the band's aliasing warning is said once, when the run images
    the band on the wall."""
    capture = required(done.capture, "capture")
    planned = run.plan.transform
    task = f"phasor field ({planned.name})"
    transform = planned.plugin
    if run.plan.transform_note:
        log.info("%s", run.plan.transform_note)
    canonical = config_to_dict(transform.config)
    needs = run.plan.needs

    def cached_field(source: Capture, source_key: str) -> tuple[PhasorField, bool]:
        key = cache_key({"capture": source_key, "transform": planned.name,
                         "options": canonical, "plugin": planned.version})
        return run.cache.get_or_compute(
            "fields", key, lambda: transform.transform(source),
            lambda p, f: write_phasor_field(p, f), read_phasor_field)

    run.events.progress(task, 0)
    field, hit = cached_field(capture.capture, capture.key)
    clean = None
    if capture.clean is not None and capture.clean_key is not None:
        clean = cached_field(capture.clean, capture.clean_key)[0]
    if not run.plan.imager_needs.time_domain:     # a time-domain imager images no wall band
        _warn_aliasing(field)
    score = variance = power = None
    if capture.count_split is not None and capture.score_key is not None:
        score = cached_field(capture.count_split.b, capture.score_key)[0]
        power = kernel_power(transform, capture.count_split.b, planned.name)
        variance = field_variance(transform, capture.count_split.b, planned.name, power=power)
    if needs.noise_variance:
        field = field.replace(variance=_training_variance(transform, capture, planned.name,
                                                          power))
    if needs.photon_counts:
        field = field.replace(counts=_training_counts(transform, capture, planned.name, power))
    run.events.progress(task, 1, 1, f"{field.n_frequencies} frequencies"
                        + (" (cached)" if hit else ""))
    run.files.write("phasor_field", lambda p: write_phasor_field(p, field),
                    keep_as=Artefact.phasor_field)
    result = TransformResult(field=field, cache_hit=hit, clean=clean, plugin=planned.name,
                             score=score, score_variance=variance)
    return dataclasses.replace(result, metrics=transform_metrics(planned.name, result))


def _training_variance(transform: PhasorTransform, capture: CaptureResult, name: str,
                       power: np.ndarray | None) -> np.ndarray:
    """The Poisson variance of the training capture's field, for a model whose likelihood
    needs it (``power``: the transform's kernel power when count splitting probed it on
    half B, whose layout is the training half's); a one-line ConfigError for
    ``model.likelihood`` naming the capture when it is not photon counts or the transform
    is not DFT-like."""
    option, purpose = "model.likelihood", "the Poisson likelihood"
    photon_counts(capture.capture, capture.label, option, purpose)
    return field_variance(transform, capture.capture, name, option, purpose, power)


def _training_counts(transform: PhasorTransform, capture: CaptureResult, name: str,
                     power: np.ndarray | None) -> PhotonCounts:
    """The training capture's photon counts in the field's wall layout, for a model whose
    likelihood is theirs; a one-line ConfigError for ``model.likelihood`` naming the capture
    when it is not photon counts or the transform is not the plain temporal DFT
    (|K(f, t)| = delta_t) that relates the counts to the field."""
    option, purpose = "model.likelihood", "the photon counts' likelihood"
    source = capture.capture
    check_counts_times(source.geometry, transform.config, capture.label)
    counts = photon_counts(source, capture.label, option, purpose).astype(np.float64)
    power = kernel_power(transform, source, name, option, purpose) if power is None else power
    if not np.allclose(power, source.delta_t ** 2, rtol=1e-6):
        raise ConfigError(option, f"{capture.label}: the {name} transform is not the plain "
                          "temporal DFT of the counts (|kernel| != delta_t), so its field "
                          f"cannot be related to them; use the fft or wavelet transform")
    layout = to_field_layout(histogram_2d(source.replace(H=counts)), source)
    return PhotonCounts(layout, float(source.t_start), float(source.delta_t),
                        count_scale(source))


def fit_stage(run: StageContext, done: StageResults) -> FitResult:
    """Split the field; fit the selected model, the interp baseline and every ``compare``
    model to its training samples; write the selected model."""
    field = required(done.transform, "transform").field
    # the run's depth range bounds a model's own depth search (rsd_prior's)
    field = field.replace(depth_range=run.plan.depths.span(
        required(done.capture, "capture").capture))
    s = run.plan.settings.split
    split = split_field(field, s.sampling, spectral=s.spectral,
                        spectral_fraction=s.spectral_fraction)
    models = []
    for planned in run.plan.models:
        try:
            report = planned.model.fit(split.train_field, on_step=_training_steps(run, planned))
        except (ConfigError, FitError) as err:
            raise named_for(err, planned.source) from None
        run.events.progress(f"fit {planned.name}", report.steps, report.steps,
                            f"loss {report.final_loss:.3g}")
        models.append(FittedModel(source=planned.source, plugin=planned.name,
                                  model=planned.model, report=report))
        if planned.source == "model":
            run.files.write("field_model", planned.model.save, kind="field_model",
                            keep_as=Artefact.model)
    return FitResult(split=split, models=tuple(models), split_metrics=split_metrics(split),
                     field_metrics={m.source: fit_metrics(m, split) for m in models})


#: ``model.<option>`` in an error's text (not a module path such as ``nlosfw.model.x``).
_MODEL_OPTION = re.compile(r"(?<![\w.])model\.(?=[a-z_])")


def named_for(err: ConfigError | FitError, source: str) -> ConfigError | FitError:
    """The error of the model fitted as ``source``, naming its options as the user does: a
    ``compare`` model's are ``compare.<label>.*``, where the model's own errors say
    ``model.*`` (the selected model and the interp baseline: unchanged)."""
    if source in ("model", "interp"):
        return err
    prefix = f"compare.{source}."
    if isinstance(err, ConfigError):
        if not err.option.startswith("model."):
            return err
        return ConfigError(prefix + err.option.removeprefix("model."), err.problem)
    return FitError(_MODEL_OPTION.sub(prefix, str(err)))


def predict_stage(run: StageContext, done: StageResults) -> ImagedFields:
    """The fields to image: true, raw (training samples, all frequencies), every model's
    prediction of the full field, each prediction scored (:mod:`nlosfw.evaluation`);
    written as ``fields/<source>.hdf5`` (``output.keep``)."""
    transformed = required(done.transform, "transform")
    field = transformed.field
    fitted = required(done.fit, "fit")
    predicted, seconds = {}, {}
    for index, fm in enumerate(fitted.models):
        run.events.progress("predict", index, len(fitted.models), f"{fm.source} ({fm.plugin})")
        start = time.perf_counter()
        predicted[fm.source] = fm.model.predict_field(
            field.wall_xyz, field.frequencies, field.geometry, field.weights,
            metadata={"source": fm.source})
        seconds[fm.source] = round(time.perf_counter() - start, 4)
    run.events.progress("predict", len(fitted.models), len(fitted.models),
                        ", ".join(fm.plugin for fm in fitted.models))
    fields = ImagedFields(true=transformed.reference, raw=fitted.split.raw_field(field),
                          predicted=predicted, seconds=seconds,
                          ceiling=None if transformed.score is None else field,
                          scores={source: prediction_scores(prediction, transformed, fitted.split)
                                  for source, prediction in predicted.items()})
    for source, f in fields.items():
        run.files.write(f"fields/{source}.hdf5", partial(write_phasor_field, field=f),
                        kind="phasor_field", keep_as=Artefact.fields)
    return fields


def _training_steps(run: StageContext, planned: PlannedModel
                    ) -> Callable[[TrainingStep], None]:
    """``on_step`` of a fit, reporting each step as ``on_training_step``."""
    return partial(_report_step, run, planned)


def _report_step(run: StageContext, planned: PlannedModel, step: TrainingStep) -> None:
    run.events.training_step(planned.source, planned.name, step.step, step.total_steps,
                             step.loss, step.val_loss)


def _warn_aliasing(field: PhasorField) -> None:
    """The band's aliasing warning, also for a field from the cache (once per run)."""
    message = band_warning(field)
    if message is not None:
        log.warning("%s", message)

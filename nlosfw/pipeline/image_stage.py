"""The last stages: every field imaged on the same voxels (``reconstruct``), and the
report files of a complete run (``report``, written by the report hooks' subscribers)."""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from functools import partial

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.hints import ImagingHints
from nlosfw.common.files import format_bytes
from nlosfw.common.logs import FILE_ONLY
from nlosfw.common.progress import accepts_progress
from nlosfw.evaluation.reference import (
    REFERENCE,
    memory_reason,
    reference_bytes,
    reference_capture,
    reference_reason,
)
from nlosfw.evaluation.splits import FieldSplit
from nlosfw.image.interface import Imager
from nlosfw.image.measured import histogram_field
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.reconstruction_io import write_reconstruction
from nlosfw.image.transient import TransientImager
from nlosfw.pipeline.context import StageContext
from nlosfw.pipeline.measure import reconstruction_metrics, truth_depth_image
from nlosfw.pipeline.results import (
    CaptureResult,
    FrequencySplit,
    Reconstructions,
    SingleFrequencyImages,
    StageResults,
    required,
)
from nlosfw.pipeline.settings import Artefact
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import PhasorField

log = logging.getLogger(__name__)


def reconstruct_stage(run: StageContext, done: StageResults) -> Reconstructions:
    """Image every field on the same voxels, then each from single frequencies alone; score
    every reconstruction against the true field's (:mod:`nlosfw.evaluation`)."""
    capture = required(done.capture, "capture").capture
    imager = run.plan.imager
    if run.plan.imager_note:
        log.info("%s", run.plan.imager_note)
    sources: dict[str, PhasorField]
    chosen: dict[FrequencySplit, int] = {}
    if done.fields is None:  # model=none: the capture's own field, imaged alone
        sources = {"true": with_capture_hints(required(done.transform, "transform").field,
                                              capture)}
    else:
        split = required(done.fit, "fit").split
        sources = {name: with_capture_hints(f, capture)
                   for name, f in done.fields.by_source().items()}
        if run.plan.imager_needs.time_domain and sources["raw"].grid_shape != \
                done.fields.true.grid_shape:
            sources["raw"] = with_capture_hints(zero_filled(split, done.fields.true), capture)
        # as in the thesis figures: images from one frequency at a time, too
        chosen = chosen_frequencies(split,
                                    run.plan.settings.reconstruction.single_frequency_images)
    true = sources["true"]
    voxels = run.plan.depths.voxels(capture, true)
    hints = settled_hints(imager.plugin, true, voxels)
    if hints is not None:
        sources = {name: field.replace(imaging_hints=hints) for name, field in sources.items()}
    log.info("%d reconstructions with %s: %d fields (%s) from all %d frequencies%s",
             len(sources) * (1 + len(chosen)), imager.name, len(sources), ", ".join(sources),
             true.n_frequencies,
             "".join(f" and from f = {true.frequencies[i]:.4g} /m ({label})"
                     for label, i in chosen.items()))
    by_source: dict[str, Reconstruction] = {}
    seconds: dict[str, float] = {}
    for source, field in sources.items():
        start = time.perf_counter()
        by_source[source] = _image(run, imager.plugin, field, voxels, f"image {source}")
        seconds[source] = round(time.perf_counter() - start, 4)
    singles = _single_frequency_images(run, imager.plugin, sources, voxels, chosen)
    reference = _reference(run, required(done.capture, "capture"), voxels, hints)
    written = {**by_source, **({} if reference is None else {REFERENCE: reference})}
    for source, recon in written.items():
        run.files.write(f"reconstructions/{source}.hdf5",
                        partial(write_reconstruction, recon=recon),
                        kind="reconstruction", keep_as=Artefact.reconstructions)
    recons = Reconstructions(voxels=voxels, by_source=by_source, seconds=seconds,
                             single_frequency=tuple(singles), imager=imager.name,
                             reference=reference)
    return dataclasses.replace(recons, metrics=reconstruction_metrics(
        imager.name, recons, truth_depth_image(capture)))


def report_stage(run: StageContext, done: StageResults) -> None:
    """The report files of a complete run (figures, tables), or of a run stopped before it
    imaged (the capture's figures), by the report subscribers."""
    results = done.complete()
    settings = run.plan.settings
    if results is not None:
        run.events.write_report(run.files, results, run.recorder.metrics, settings)
    elif done.capture is not None and done.reconstructions is None:
        span = run.plan.depths.span(done.capture.capture)
        run.events.write_capture_report(run.files, done.capture, span, run.recorder.metrics,
                                        settings)
    else:  # the report stage runs only after all the others, or after a stop
        raise ValueError("the report stage needs every stage's results")


def with_capture_hints(field: PhasorField, capture: Capture) -> PhasorField:
    """``field`` carrying the capture's imaging hints (a field model's prediction does not
    inherit the transform's metadata)."""
    if capture.imaging_hints is None or field.imaging_hints is not None:
        return field
    return field.replace(imaging_hints=capture.imaging_hints)


def settled_hints(imager: Imager, field: PhasorField, voxels: np.ndarray
                  ) -> ImagingHints | None:
    """The settings a transient imager takes from the data (falloff, Wiener SNR), found
    once from the capture's own field ``field`` so that every source and the reference
    picture are imaged alike (the line the log says about them); None for another imager."""
    if not isinstance(imager, TransientImager):
        return None
    hints = imager.settled_hints(field, voxels)
    log.info("imaging settings of %s: %s", imager.imager_name, hints.origin)
    return hints


def zero_filled(split: FieldSplit, field: PhasorField) -> PhasorField:
    """The training samples of ``field`` on its full grid, zeros elsewhere: the ``raw``
    source for imagers that image only the full wall grid (a zero adds nothing to a
    back-projection or to the light-cone convolution)."""
    values = np.where(split.spatial_mask[None], field.values, 0).astype(field.values.dtype)
    return field.replace(values=values, zero_filled=True)


def chosen_frequencies(split: FieldSplit, count: int) -> dict[FrequencySplit, int]:
    """Up to ``count`` frequency indices to show alone: a training one near the top of the
    band, then a held-out one (if any), by label."""
    train = np.asarray(split.train_frequencies)
    held = np.asarray(split.heldout_frequencies)
    chosen: dict[FrequencySplit, int] = {"training": int(train[int(0.75 * (train.size - 1))])}
    if held.size:
        chosen["held-out"] = int(held[held.size // 2])
    return dict(list(chosen.items())[:count])


def _image(run: StageContext, imager: Imager, field: PhasorField, voxels: np.ndarray,
           task: str) -> Reconstruction:
    """One reconstruction, reporting the imager's blocks as the task's progress (when it
    reports them through ``on_progress``)."""
    run.events.progress(task, 0)
    if accepts_progress(imager.reconstruct):
        return imager.reconstruct(field, voxels, on_progress=run.events.progress_callback(task))
    recon = imager.reconstruct(field, voxels)
    run.events.progress(task, 1, 1)
    return recon


def _reference(run: StageContext, capture: CaptureResult, voxels: np.ndarray,
               hints: ImagingHints | None) -> Reconstruction | None:
    """The reference picture (:mod:`nlosfw.evaluation.reference`), imaged with the sources'
    settings ``hints`` when given, or None (the log says why)."""
    field = _reference_field(run, capture, voxels)
    if field is None:
        return None
    if hints is not None:
        field = field.replace(imaging_hints=hints)
    start = time.perf_counter()
    recon = _image(run, run.plan.imager.plugin, field, voxels,
                   "image the histograms (reference)")
    log.info("reference picture imaged by %s in %.3g s", run.plan.imager.name,
             time.perf_counter() - start)
    return recon


def _reference_field(run: StageContext, result: CaptureResult,
                     voxels: np.ndarray) -> PhasorField | None:
    """The field of the capture's histograms at their native bin width (every positive DFT
    bin, the run's ``fft`` transform options kept), carrying the capture's imaging hints;
    None, with the reason in the log, when the run makes no reference picture (run.log
    only where it does not apply, a warning when ``reconstruction.histogram_reference``
    asked for one)."""
    settings = run.plan.settings
    choice = settings.reconstruction.histogram_reference
    imager = run.plan.imager
    reason = reference_reason(choice, imager.name, run.plan.imager_needs.time_domain,
                              result.source == "file", result.capture)
    if reason is not None:
        _no_reference(choice is True, reason)
        return None
    capture = reference_capture(result.capture, result.count_split)
    depths = np.unique(np.asarray(voxels, dtype=float)[..., 2])
    needed = reference_bytes(capture, depths, imager.plugin.config)
    reason = memory_reason(needed, settings.limits.allow_large)
    if reason is not None:
        _no_reference(choice is True, reason)
        return None
    transform = run.plan.transform.plugin
    field = histogram_field(capture, transform.config
                            if isinstance(transform, FFTTransform) else None)
    if field.imaging_hints is None and result.capture.imaging_hints is not None:
        field = field.replace(imaging_hints=result.capture.imaging_hints)
    log.info("reference picture: the histograms at native bins, %d frequencies to %.4g "
             "cycles/m (estimated memory %s; not scored)", field.n_frequencies,
             float(field.frequencies.max()), format_bytes(needed))
    return field


def _no_reference(asked: bool, reason: str) -> None:
    """Log why no reference picture is made: a console warning when
    ``reconstruction.histogram_reference=true`` asked for one, else run.log only."""
    log.log(logging.WARNING if asked else logging.INFO, "no reference picture: %s", reason,
            extra=None if asked else FILE_ONLY)


def _single_frequency_images(run: StageContext, imager: Imager,
                             sources: Mapping[str, PhasorField], voxels: np.ndarray,
                             chosen: dict[FrequencySplit, int]) -> list[SingleFrequencyImages]:
    """Every field (by source, ``true`` first) imaged from each chosen frequency alone."""
    if not chosen:
        return []
    task, total, count = "single-frequency images", len(chosen) * len(sources), 0
    singles = []
    for label, index in chosen.items():
        images = {}
        for source, field in sources.items():
            run.events.progress(task, count, total, f"{source} at {label}")
            images[source] = imager.reconstruct(field.select(frequency_index=[index]),
                                                voxels)
            count += 1
        singles.append(SingleFrequencyImages(
            index=index, frequency=float(sources["true"].frequencies[index]), split=label,
            by_source=images))
    run.events.progress(task, total, total, ", ".join(f"f = {s.frequency:.4g} /m ({s.split})"
                                                      for s in singles))
    return singles

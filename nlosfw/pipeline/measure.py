"""The sections of :class:`~nlosfw.pipeline.metrics.RunMetrics` each stage hands on in its
result: what it made, in numbers, and its scores, computed by :mod:`nlosfw.evaluation` and
written here into the sections' types (the metrics recorder only records them)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.evaluation.field_scores import denoising_errors, field_metrics
from nlosfw.evaluation.heldout import heldout_scores
from nlosfw.evaluation.image_scores import scored
from nlosfw.evaluation.splits import FieldSplit, SpatialPattern
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.pipeline.metrics import (
    CaptureMetrics,
    CountSplittingMetrics,
    DenoisingMetrics,
    FieldMetrics,
    FitMetrics,
    HeldoutMeasurementMetrics,
    ImageScores,
    PreprocessingStep,
    ReconstructionMetrics,
    SingleFrequencyMetrics,
    SplitErrors,
    SplitMetrics,
    TransformMetrics,
)
from nlosfw.pipeline.results import (
    CaptureResult,
    FittedModel,
    PredictionScores,
    Reconstructions,
    TransformResult,
)
from nlosfw.transform.field import PhasorField


def capture_metrics(result: CaptureResult) -> CaptureMetrics:
    """Where the capture came from, its preprocessing, its shape, timing and total signal
    (of half A with count splitting)."""
    capture = result.capture
    halves = result.count_split
    count_splitting = None if halves is None else CountSplittingMetrics(
        seed=halves.seed, count_scale=halves.count_scale, counts_a=halves.counts_a,
        counts_b=halves.counts_b)
    return CaptureMetrics(
        source=result.source,
        path=None if result.path is None else str(result.path),
        format=result.format,
        preprocessing=tuple(PreprocessingStep(option=s.option, value=s.value, source=s.source,
                                              effect=s.effect) for s in result.steps),
        simulator=result.simulator, cache_hit=result.cache_hit,
        shape=tuple(int(n) for n in capture.H.shape), kind=capture.kind,
        delta_t=float(capture.delta_t), t_start=float(capture.t_start),
        total=float(np.sum(capture.H, dtype=np.float64)),
        noise=capture.scene_info.get("noise"), count_splitting=count_splitting)


def truth_depth_image(capture: Capture) -> np.ndarray | None:
    """The scene's true depth seen from the wall as a (Y, X) image (y along rows), from
    ``scene_info["ground_truth"]["depth"]`` (stored (X, Y)); None without one."""
    truth = (capture.scene_info.get("ground_truth") or {}).get("depth")
    if truth is None:
        return None
    depth = np.asarray(truth, dtype=float)
    return depth.T if depth.ndim == 2 else None


def transform_metrics(name: str, result: TransformResult) -> TransformMetrics:
    """The transform plugin, whether its field came from the cache, its band and grid."""
    field = result.field
    ny, nx = field.grid_shape
    return TransformMetrics(
        name=name, cache_hit=result.cache_hit, n_frequencies=field.n_frequencies,
        frequency_band=(float(field.frequencies.min()), float(field.frequencies.max())),
        grid=(int(ny), int(nx)))


def split_metrics(split: FieldSplit) -> SplitMetrics:
    """The spatial pattern and the sizes of a split."""
    sampling = split.sampling
    random = sampling.pattern == SpatialPattern.random
    return SplitMetrics(
        pattern="random" if random else "grid", spatial_step=int(sampling.step),
        spatial_fraction=sampling.kept_fraction if random else None,
        seed=int(sampling.seed) if random else None,
        wall_samples=int(split.spatial_mask.size),
        train_samples=int(split.spatial_mask.sum()), undersampling=split.undersampling,
        train_frequencies=int(split.train_frequencies.size),
        heldout_frequencies=int(split.heldout_frequencies.size))


def fit_metrics(fitted: FittedModel, split: FieldSplit) -> FieldMetrics:
    """A fitted model's size against its training data, and how its fit went."""
    n_parameters, values = int(fitted.model.n_parameters), split.n_train_values
    seed = getattr(fitted.model.config, "seed", None)
    return FieldMetrics(plugin=fitted.plugin, seed=None if seed is None else int(seed),
                        n_parameters=n_parameters, training_values=values,
                        parameters_per_value=n_parameters / values,
                        fit=FitMetrics.of(fitted.report))


def denoising_metrics(clean: PhasorField, noisy: PhasorField,
                      predicted: PhasorField) -> DenoisingMetrics:
    """Errors against the noise-free field: of the noisy full field and of a prediction
    (:func:`nlosfw.evaluation.field_scores.denoising_errors`; null, with why, where
    undefined)."""
    values, reasons = denoising_errors(clean, noisy, predicted)
    return DenoisingMetrics(**values, null_reasons=reasons or None)


def heldout_measurement_metrics(predicted: PhasorField, measured: PhasorField,
                                variance: np.ndarray, split: FieldSplit
                                ) -> HeldoutMeasurementMetrics:
    """Count splitting: a prediction's error at the held-out wall points against half B's
    field, its noise floor and the excess
    (:func:`nlosfw.evaluation.heldout.heldout_scores`)."""
    score = heldout_scores(predicted.values, measured.values, variance, split.spatial_mask)
    values, reasons = score.scores
    return HeldoutMeasurementMetrics(**values, n_samples=score.n_samples,
                                     null_reasons=reasons or None)


def prediction_scores(prediction: PhasorField, transformed: TransformResult,
                      split: FieldSplit) -> PredictionScores:
    """A prediction of the full field scored against the transform's reference field (half
    B's with count splitting): on the protocol's sets, the held-out measurement (count
    splitting) and against the noise-free field (scenes with noise)."""
    true, clean = transformed.reference, transformed.clean
    variance = transformed.score_variance
    heldout = (None if variance is None
               else heldout_measurement_metrics(prediction, true, variance, split))
    return PredictionScores(
        splits=SplitErrors.of(field_metrics(true, prediction, split), heldout),
        denoising=None if clean is None else denoising_metrics(clean, true, prediction))


def image_scores(recons: Mapping[str, Reconstruction],
                 seconds: Mapping[str, float] | None = None,
                 truth_depth: np.ndarray | None = None) -> dict[str, ImageScores]:
    """Every reconstruction scored against the ``true`` one
    (:func:`nlosfw.evaluation.image_scores.scored`: a score that cannot be computed is
    None, with why); ``truth_depth`` (Y, X) adds the depth RMSE."""
    reference = recons["true"]
    scores = {}
    for source, recon in recons.items():
        values, reasons = scored(reference, recon, truth_depth)
        scores[source] = ImageScores(**values,
                                     seconds=None if seconds is None else seconds[source],
                                     null_reasons=reasons or None)
    return scores


def reconstruction_metrics(imager: str, recons: Reconstructions,
                           truth_depth: np.ndarray | None = None) -> ReconstructionMetrics:
    """Scores of every reconstruction, whole band and single frequencies; ``truth_depth``
    (Y, X), the scene's true depth seen from the wall, adds each one's depth RMSE."""
    depths = np.asarray(recons.voxels[:, 0, 0, 2], dtype=float)
    steps = np.diff(depths)
    even = steps.size > 0 and bool(np.allclose(steps, steps[0], rtol=1e-6, atol=0))
    return ReconstructionMetrics(
        imager=imager, reference="true",
        depths=tuple(float(d) for d in depths), depth_planes=int(depths.size),
        depth_spacing=float(steps[0]) if even else None,
        sources=image_scores(recons.by_source, recons.seconds, truth_depth),
        single_frequency={
            str(single.index): SingleFrequencyMetrics(frequency=single.frequency,
                                                      split=single.split,
                                                      sources=image_scores(single.by_source))
            for single in recons.single_frequency})

"""The metrics of each stage's results (the sections of
:class:`~nlosfw.pipeline.metrics.RunMetrics`)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.scores import scored
from nlosfw.model.heldout import HeldoutMeasurement, heldout_measurement
from nlosfw.model.protocol import FieldSplit, SpatialPattern
from nlosfw.pipeline.metrics import (
    CaptureMetrics,
    DenoisingMetrics,
    FieldMetrics,
    FitMetrics,
    HeldoutMeasurementMetrics,
    ImageScores,
    PreprocessingStep,
    ReconstructionMetrics,
    SingleFrequencyMetrics,
    SplitMetrics,
    ThinningMetrics,
    TransformMetrics,
)
from nlosfw.pipeline.nulls import is_number, not_finite
from nlosfw.pipeline.results import CaptureResult, FittedModel, Reconstructions, TransformResult
from nlosfw.transform.field import PhasorField


def capture_metrics(result: CaptureResult) -> CaptureMetrics:
    """Where the capture came from, its preprocessing, its shape, timing and total signal
    (of half A with count splitting)."""
    capture = result.capture
    halves = result.thinning
    thinning = None if halves is None else ThinningMetrics(
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
        noise=capture.scene_info.get("noise"), thinning=thinning)


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
    (null, with why, where undefined: a zero noise-free field, an error of zero)."""
    norm = float(np.linalg.norm(clean.values))
    if not norm > 0:
        why = "the noise-free field is zero (the scene reflects nothing): no error relative to it"
        return DenoisingMetrics(noisy_relative_l2=None, relative_l2=None, gain_db=None,
                                null_reasons=dict.fromkeys(
                                    ("noisy_relative_l2", "relative_l2", "gain_db"), why))

    def rel(field: PhasorField) -> float:
        return float(np.linalg.norm(field.values - clean.values)) / norm

    noisy_error, model_error = rel(noisy), rel(predicted)
    if noisy_error > 0 and model_error > 0:
        return DenoisingMetrics(noisy_relative_l2=noisy_error, relative_l2=model_error,
                                gain_db=float(20 * np.log10(noisy_error / model_error)))
    why = ("the prediction equals the noise-free field: the gain is infinite"
           if model_error == 0 else "the noisy field equals the noise-free field (no noise)")
    return DenoisingMetrics(noisy_relative_l2=noisy_error, relative_l2=model_error,
                            gain_db=None, null_reasons={"gain_db": why})


def heldout_measurement_metrics(predicted: PhasorField, measured: PhasorField,
                                variance: np.ndarray, split: FieldSplit
                                ) -> HeldoutMeasurementMetrics:
    """Count splitting: a prediction's error at the held-out wall points against half B's
    field, its noise floor and the excess (:func:`nlosfw.model.heldout.heldout_measurement`)."""
    held = ~np.asarray(split.spatial_mask, dtype=bool)
    at_held = np.asarray(measured.values)[:, held]
    if held.any() and not float(np.sum(np.abs(at_held) ** 2)) > 0:
        why = "half B's field is zero at the held-out wall points: no error relative to it"
        return HeldoutMeasurementMetrics(
            nmse_db=None, floor_db=None, excess_db=None, excess=None, n_samples=at_held.size,
            null_reasons=dict.fromkeys(("nmse_db", "floor_db", "excess_db", "excess"), why))
    score = heldout_measurement(predicted.values, measured.values, variance, split.spatial_mask)
    db = HeldoutMeasurement.db
    reasons = {}
    if db(score.error) is None:
        reasons["nmse_db"] = ("the prediction equals half B's field at the held-out points: "
                              "zero error" if score.error == 0 else not_finite(score.error))
    if db(score.floor) is None:
        reasons["floor_db"] = ("half B's field carries no noise variance at the held-out "
                               "points" if score.floor == 0 else not_finite(score.floor))
    if db(score.excess) is None:
        reasons["excess_db"] = ("the error is within the noise floor (excess <= 0)"
                                if is_number(score.excess) else not_finite(score.excess))
    excess = score.excess if is_number(score.excess) else None
    if excess is None:
        reasons["excess"] = not_finite(score.excess)
    return HeldoutMeasurementMetrics(nmse_db=db(score.error), floor_db=db(score.floor),
                                     excess_db=db(score.excess), excess=excess,
                                     n_samples=score.n_samples, null_reasons=reasons or None)


def image_scores(recons: Mapping[str, Reconstruction],
                 seconds: Mapping[str, float] | None = None,
                 truth_depth: np.ndarray | None = None) -> dict[str, ImageScores]:
    """Every reconstruction scored against the ``true`` one
    (:func:`nlosfw.image.scores.scored`: a score that cannot be computed is None, with
    why); ``truth_depth`` (Y, X) adds the depth RMSE."""
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

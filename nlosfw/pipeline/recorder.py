"""The run's metrics, recorded by a subscriber to the run hooks.

:class:`MetricsRecorder` is registered on the run's plugin manager for the length of the
run. It turns each stage's typed result (``on_stage_result``) into its section of
:class:`~nlosfw.pipeline.metrics.RunMetrics` (:mod:`nlosfw.pipeline.measure`) and each
stage's time (``on_stage_end``) into ``timings``; the engine only says how the run ended.
"""

from __future__ import annotations

from msgspec.structs import replace

from nlosfw.model.protocol import FieldSplit, field_metrics
from nlosfw.pipeline.measure import (
    capture_metrics,
    denoising_metrics,
    fit_metrics,
    heldout_measurement_metrics,
    reconstruction_metrics,
    split_metrics,
    transform_metrics,
    truth_depth_image,
)
from nlosfw.pipeline.metrics import FieldMetrics, RunError, RunInfo, RunMetrics, SplitErrors, Status
from nlosfw.pipeline.nulls import explained
from nlosfw.pipeline.results import (
    CaptureResult,
    FitResult,
    ImagedFields,
    Reconstructions,
    TransformResult,
)
from nlosfw.plugins import hookimpl


class MetricsRecorder:
    """Builds one run's :class:`RunMetrics` from the hooks the run calls."""

    def __init__(self, info: RunInfo) -> None:
        self.metrics = RunMetrics(run=info)
        """The metrics so far (all of them once the run has ended)."""
        self._capture: CaptureResult | None = None
        self._transform: TransformResult | None = None
        self._split: FieldSplit | None = None

    @hookimpl
    def on_stage_result(self, stage: str, result: object) -> None:
        """Record the section of a stage's result."""
        m = self.metrics
        if isinstance(result, CaptureResult):
            self._capture = result
            run = m.run if result.format is None else replace(m.run,
                                                              capture_format=result.format)
            self.metrics = replace(m, run=run, capture=capture_metrics(result))
        elif isinstance(result, TransformResult):
            self._transform = result
            self.metrics = replace(m, transform=transform_metrics(result.plugin, result))
        elif isinstance(result, FitResult):
            self._split = result.split
            self.metrics = replace(m, split=split_metrics(result.split), field={
                fitted.source: fit_metrics(fitted, result.split) for fitted in result.models})
        elif isinstance(result, ImagedFields):
            self._record_predictions(result)
        elif isinstance(result, Reconstructions):
            truth = None if self._capture is None else truth_depth_image(self._capture.capture)
            self.metrics = replace(m, reconstruction=reconstruction_metrics(
                result.imager, result, truth))

    @hookimpl
    def on_stage_end(self, stage: str, seconds: float) -> None:
        """Record a stage's time."""
        self._record_time(stage, seconds)

    def finish(self, status: Status, total_seconds: float, error: RunError | None = None,
               stopped_after: str | None = None) -> RunMetrics:
        """The final metrics: how the run ended, and its total time; a NaN or inf a section
        of scores still holds is null there, with why (:func:`~nlosfw.pipeline.nulls.explained`)."""
        self._record_time("total", total_seconds)
        run = self.metrics.run if stopped_after is None else replace(
            self.metrics.run, stopped_after=stopped_after)
        self.metrics = explained(replace(self.metrics, status=status, error=error, run=run))
        return self.metrics

    def bare(self, error: RunError) -> RunMetrics:
        """The record of a failed run whose sections cannot be written (a value their types
        do not admit): what ran, the error and the timings only."""
        return RunMetrics(run=self.metrics.run, status="failed", error=error,
                          timings=self.metrics.timings)

    def _record_predictions(self, fields: ImagedFields) -> None:
        """Every model's field errors against the full field (and denoising gains)."""
        if self._transform is None or self._split is None or self.metrics.field is None:
            raise ValueError("predictions are recorded after the transform and fit stages")
        true, clean = self._transform.reference, self._transform.clean
        variance = self._transform.score_variance
        entries: dict[str, FieldMetrics] = dict(self.metrics.field)
        for source, prediction in fields.predicted.items():
            heldout = (None if variance is None else heldout_measurement_metrics(
                prediction, true, variance, self._split))
            entries[source] = replace(
                entries[source], predict_seconds=fields.seconds.get(source),
                splits=SplitErrors.of(field_metrics(true, prediction, self._split), heldout),
                denoising=(None if clean is None
                           else denoising_metrics(clean, true, prediction)))
        self.metrics = replace(self.metrics, field=entries)

    def _record_time(self, name: str, seconds: float) -> None:
        timings = replace(self.metrics.timings, **{name: round(seconds, 4)})
        self.metrics = replace(self.metrics, timings=timings)

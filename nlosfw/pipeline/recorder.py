"""The run's metrics, recorded by a subscriber to the run hooks.

:class:`MetricsRecorder` is registered on the run's plugin manager for the length of the
run. It copies the section each stage's typed result carries (``on_stage_result``: the
stage computed it, its scores through :mod:`nlosfw.evaluation`) into
:class:`~nlosfw.pipeline.metrics.RunMetrics`, and each stage's time (``on_stage_end``)
into ``timings``; it computes nothing and keeps no result. The engine only says how the
run ended.
"""

from __future__ import annotations

from msgspec.structs import replace

from nlosfw.pipeline.metrics import FieldMetrics, RunError, RunInfo, RunMetrics, Status
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

    @hookimpl
    def on_stage_result(self, stage: str, result: object) -> None:
        """Record the section a stage's result carries."""
        m = self.metrics
        if isinstance(result, CaptureResult):
            run = m.run if result.format is None else replace(m.run,
                                                              capture_format=result.format)
            self.metrics = replace(m, run=run, capture=result.metrics)
        elif isinstance(result, TransformResult):
            self.metrics = replace(m, transform=result.metrics)
        elif isinstance(result, FitResult):
            self.metrics = replace(m, split=result.split_metrics,
                                   field=dict(result.field_metrics))
        elif isinstance(result, ImagedFields):
            self._record_predictions(result)
        elif isinstance(result, Reconstructions):
            self.metrics = replace(m, reconstruction=result.metrics)

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
        """Every prediction's time and scores, into its model's entry."""
        if self.metrics.field is None:
            raise ValueError("predictions are recorded after the fit stage")
        entries: dict[str, FieldMetrics] = dict(self.metrics.field)
        for source, scores in fields.scores.items():
            entries[source] = replace(entries[source], predict_seconds=fields.seconds.get(source),
                                      splits=scores.splits, denoising=scores.denoising)
        self.metrics = replace(self.metrics, field=entries)

    def _record_time(self, name: str, seconds: float) -> None:
        timings = replace(self.metrics.timings, **{name: round(seconds, 4)})
        self.metrics = replace(self.metrics, timings=timings)

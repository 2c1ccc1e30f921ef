"""The run engine: a plan's stages in order, reported through the run hooks.

A run is a :class:`RunPlan` (validated settings and built plugins, :func:`make_plan`)
run by a :class:`Pipeline` into a run directory; its stages hand each other typed results
(:mod:`~nlosfw.pipeline.results`) and its numbers are a :class:`RunMetrics`
(``metrics.json``). No Hydra, rich or matplotlib here: the command line composes the
configuration and draws the console, the report plugin draws the figures.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these.
"""

from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.pipeline.budget import memory_summary, process_memory
    from nlosfw.pipeline.cache import cache_entries, file_digest
    from nlosfw.pipeline.engine import STAGES, Pipeline, objective
    from nlosfw.pipeline.events import RunEvents
    from nlosfw.pipeline.files import PLANNED_NAMES, RunFiles
    from nlosfw.pipeline.metrics import (
        SCHEMA_VERSION,
        TIMING_FIELDS,
        FieldMetrics,
        ImageScores,
        ReconstructionMetrics,
        RunInfo,
        RunMetrics,
        metrics_outline,
        metrics_schema,
        without_timings,
    )
    from nlosfw.pipeline.metrics_versions import metrics_as_current
    from nlosfw.pipeline.plan import PlainConfig, Planned, PlannedModel, RunPlan, make_plan
    from nlosfw.pipeline.results import (
        CaptureResult,
        FitResult,
        FittedModel,
        ImagedFields,
        PredictionScores,
        Reconstructions,
        RunOutput,
        RunResults,
        SingleFrequencyImages,
        StageResults,
        TransformResult,
    )
    from nlosfw.pipeline.settings import Artefact, PublishedTable, RunSettings, run_settings

__all__ = [
    "Artefact",
    "CaptureResult",
    "FieldMetrics",
    "FitResult",
    "FittedModel",
    "ImageScores",
    "ImagedFields",
    "PLANNED_NAMES",
    "Pipeline",
    "PlainConfig",
    "Planned",
    "PlannedModel",
    "PredictionScores",
    "PublishedTable",
    "ReconstructionMetrics",
    "Reconstructions",
    "RunEvents",
    "RunFiles",
    "RunInfo",
    "RunMetrics",
    "RunOutput",
    "RunPlan",
    "RunResults",
    "RunSettings",
    "SCHEMA_VERSION",
    "STAGES",
    "SingleFrequencyImages",
    "StageResults",
    "TIMING_FIELDS",
    "TransformResult",
    "cache_entries",
    "file_digest",
    "make_plan",
    "memory_summary",
    "metrics_as_current",
    "metrics_outline",
    "metrics_schema",
    "objective",
    "process_memory",
    "run_settings",
    "without_timings",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

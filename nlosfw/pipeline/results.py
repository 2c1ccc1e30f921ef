"""What the stages of a run hand each other: typed, frozen results.

capture -> :class:`CaptureResult` -> transform -> :class:`TransformResult` -> split and
fit -> :class:`FitResult` (the :class:`~nlosfw.evaluation.FieldSplit` and one
:class:`FittedModel` per source) -> predict -> :class:`ImagedFields` -> reconstruct ->
:class:`Reconstructions`; :class:`RunResults` holds them all for the report stage. The
run's numbers are :class:`nlosfw.pipeline.metrics.RunMetrics`: each stage computes its
section (its scores through :mod:`nlosfw.evaluation`) and hands it on in its result
(``metrics``, ``scores``), which the metrics recorder records as it is.

A *source* is a field's role in the run: ``true`` (the full field), ``raw`` (its
training samples at every frequency, :meth:`~nlosfw.evaluation.FieldSplit.raw_field`),
``model``, ``interp`` and the ``compare`` labels. Mappings by source keep that order
and are read-only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Literal, TypeVar

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.preprocess import AppliedStep
from nlosfw.common.errors import DataError
from nlosfw.evaluation.count_splitting import CountSplit
from nlosfw.evaluation.splits import FieldSplit
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.model.interface import FieldModel, FitReport
from nlosfw.pipeline.metrics import (
    CaptureMetrics,
    DenoisingMetrics,
    FieldMetrics,
    ReconstructionMetrics,
    RunMetrics,
    SplitErrors,
    SplitMetrics,
    TransformMetrics,
)
from nlosfw.transform.field import PhasorField

FrequencySplit = Literal["training", "held-out"]
R = TypeVar("R")


def required(result: R | None, stage: str) -> R:
    """The result of ``stage`` (an earlier stage of the run; the engine runs them in order)."""
    if result is None:
        raise ValueError(f"the {stage} stage has not run")
    return result


def _frozen_mapping(mapping: Mapping[str, object]) -> Mapping[str, object]:
    return MappingProxyType(dict(mapping))


@dataclass(frozen=True, eq=False)
class CaptureResult:
    """The run's capture, where it came from, and its cache key.

    For a scene with noise, ``clean`` is the noise-free capture (cached under
    ``clean_key``) that gives the denoising metrics.
    """

    capture: Capture
    key: str
    """Cache key: the file's digest, or everything that produced the simulation."""
    source: Literal["simulated", "file"]
    label: str
    """What the run images, for titles: ``<file name> (<format>)`` or ``<scene> (<simulator>)``."""
    path: Path | None = None
    """The file read (source ``file``)."""
    format: str | None = None
    """The capture format that read it (source ``file``)."""
    simulator: str | None = None
    """The simulator plugin (source ``simulated``)."""
    steps: tuple[AppliedStep, ...] = ()
    """The preprocessing applied to ``capture`` (and to ``clean``)."""
    cache_hit: bool | None = None
    """Whether the simulated capture came from the cache."""
    clean: Capture | None = None
    clean_key: str | None = None
    count_split: CountSplit | None = None
    """Count splitting (``split.count_splitting``): ``capture`` is half A (the models train
    on it), ``count_split.b`` is half B (cached under ``score_key``: every score uses it),
    and ``clean`` is the noise-free capture at half the exposure."""
    score_key: str | None = None
    metrics: CaptureMetrics | None = None
    """The capture's section of the run's metrics (the capture stage's last step)."""

    def __post_init__(self) -> None:
        if (self.clean is None) != (self.clean_key is None):
            raise ValueError("CaptureResult: clean and clean_key come together")
        if (self.count_split is None) != (self.score_key is None):
            raise ValueError("CaptureResult: count_split and score_key come together")
        if (self.source == "file") != (self.path is not None and self.format is not None):
            raise ValueError("CaptureResult: a path and a format exactly when the source is a "
                             "file")

    @property
    def truth_depth(self) -> np.ndarray | None:
        """The scene's ground-truth depth (X, Y) from ``scene_info``, when it has one."""
        truth = (self.capture.scene_info.get("ground_truth") or {}).get("depth")
        return None if truth is None else np.asarray(truth, dtype=float)


@dataclass(frozen=True, eq=False)
class TransformResult:
    """The capture's phasor field (and the noise-free capture's, for noisy scenes)."""

    field: PhasorField
    cache_hit: bool
    clean: PhasorField | None = None
    plugin: str = ""
    """The transform plugin that made ``field``."""
    score: PhasorField | None = None
    """Count splitting: the field of half B (``field`` is half A's), which every score uses."""
    score_variance: np.ndarray | None = None
    """Count splitting: the variance B's Poisson noise adds to each sample of ``score``
    (F, Y, X) (:func:`nlosfw.evaluation.noise_floor.field_variance`)."""
    metrics: TransformMetrics | None = None
    """The transform's section of the run's metrics."""

    @property
    def reference(self) -> PhasorField:
        """The field scores are measured against: half B's with count splitting, else
        ``field``."""
        return self.field if self.score is None else self.score


@dataclass(frozen=True, eq=False)
class FittedModel:
    """One fitted field model: its role in the run, its plugin, the model and its report."""

    source: str
    plugin: str
    model: FieldModel
    report: FitReport


@dataclass(frozen=True, eq=False)
class FitResult:
    """The split of the field and every field model fitted to its training samples."""

    split: FieldSplit
    models: tuple[FittedModel, ...]
    split_metrics: SplitMetrics | None = None
    """The split's section of the run's metrics."""
    field_metrics: Mapping[str, FieldMetrics] = dataclasses.field(default_factory=dict)
    """Each fitted model's size and fit, by source (its scores come with the predictions)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "field_metrics", _frozen_mapping(self.field_metrics))
        sources = [m.source for m in self.models]
        if len(set(sources)) != len(sources):
            raise ValueError(f"FitResult: sources must be unique, got {sources}")


@dataclass(frozen=True, eq=False)
class PredictionScores:
    """A prediction's field scores (:mod:`nlosfw.evaluation`), as the run records them."""

    splits: SplitErrors
    """On the protocol's sets (and, with count splitting, the held-out measurement)."""
    denoising: DenoisingMetrics | None = None
    """Against the noise-free field (scenes with noise)."""


@dataclass(frozen=True, eq=False)
class ImagedFields:
    """The fields that are imaged: ``true``, ``raw`` and each fitted model's prediction."""

    true: PhasorField
    raw: PhasorField
    predicted: Mapping[str, PhasorField]
    """Predictions of the full field by source, in the order the models were fitted."""
    seconds: Mapping[str, float] = dataclasses.field(default_factory=dict)
    """Time each prediction took, by source."""
    ceiling: PhasorField | None = None
    """Count splitting: half A's full field (``true`` is half B's); scored against ``true``
    it is the ceiling of what a model trained on A can reach."""
    scores: Mapping[str, PredictionScores] = dataclasses.field(default_factory=dict)
    """Each prediction's field scores, by source."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "predicted", _frozen_mapping(self.predicted))
        object.__setattr__(self, "seconds", _frozen_mapping(self.seconds))
        object.__setattr__(self, "scores", _frozen_mapping(self.scores))
        if {"true", "raw", "ceiling"} & set(self.predicted):
            raise ValueError("ImagedFields: 'true', 'raw' and 'ceiling' are not prediction "
                             "sources")

    def items(self) -> Iterator[tuple[str, PhasorField]]:
        """(source, field) for every field: true, raw, the ceiling (count splitting), then
        the predictions."""
        yield "true", self.true
        yield "raw", self.raw
        if self.ceiling is not None:
            yield "ceiling", self.ceiling
        yield from self.predicted.items()

    def by_source(self) -> Mapping[str, PhasorField]:
        return _frozen_mapping(dict(self.items()))  # type: ignore[return-value]


@dataclass(frozen=True, eq=False)
class SingleFrequencyImages:
    """Reconstructions of every field from one frequency alone (as in the thesis's figures)."""

    index: int
    """Index into the full field's frequencies."""
    frequency: float
    split: FrequencySplit
    by_source: Mapping[str, Reconstruction]

    def __post_init__(self) -> None:
        object.__setattr__(self, "by_source", _frozen_mapping(self.by_source))


@dataclass(frozen=True, eq=False)
class Reconstructions:
    """Every imaged field's reconstruction on the same voxels, by source (``true`` first)."""

    voxels: np.ndarray
    by_source: Mapping[str, Reconstruction]
    seconds: Mapping[str, float]
    """Time each reconstruction took, by source."""
    single_frequency: tuple[SingleFrequencyImages, ...] = ()
    imager: str = ""
    """The imager plugin that made them."""
    reference: Reconstruction | None = None
    """The capture's histograms at their native bin width, imaged by the same imager on the
    same voxels (``reconstruction.histogram_reference``, :mod:`nlosfw.evaluation.reference`):
    the reference picture shown beside the sources, never scored."""
    metrics: ReconstructionMetrics | None = None
    """Every reconstruction's scores against the true field's (and the planes): the
    reconstruction section of the run's metrics."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "by_source", _frozen_mapping(self.by_source))
        object.__setattr__(self, "seconds", _frozen_mapping(self.seconds))
        if next(iter(self.by_source), None) != "true":
            raise ValueError("Reconstructions: the first source must be 'true' (the reference)")


@dataclass(frozen=True, eq=False)
class RunResults:
    """Everything a complete run produced, for the report stage (figures, tables)."""

    capture: CaptureResult
    transform: TransformResult
    fit: FitResult | None
    """None for ``model=none`` (the capture imaged alone: no split, no field model)."""
    fields: ImagedFields | None
    """None for ``model=none``: the only field imaged is the capture's (``true``)."""
    reconstructions: Reconstructions


@dataclass(frozen=True, eq=False)
class StageResults:
    """What the stages of one run produced, as far as it went (None: the stage did not run,
    because ``stop_after`` ended the run earlier or a stage failed)."""

    capture: CaptureResult | None = None
    transform: TransformResult | None = None
    fit: FitResult | None = None
    fields: ImagedFields | None = None
    reconstructions: Reconstructions | None = None

    def with_result(self, result: object) -> StageResults:
        """These results with a stage's ``result`` added (by its type)."""
        if isinstance(result, CaptureResult):
            return dataclasses.replace(self, capture=result)
        if isinstance(result, TransformResult):
            return dataclasses.replace(self, transform=result)
        if isinstance(result, FitResult):
            return dataclasses.replace(self, fit=result)
        if isinstance(result, ImagedFields):
            return dataclasses.replace(self, fields=result)
        if isinstance(result, Reconstructions):
            return dataclasses.replace(self, reconstructions=result)
        raise TypeError(f"not a stage result: {type(result).__name__}")

    def complete(self) -> RunResults | None:
        """All of them as :class:`RunResults`, or None when a stage did not run (fit and
        predict run in every plan but ``model=none``'s, which images the capture alone)."""
        if (self.capture is None or self.transform is None or self.reconstructions is None
                or (self.fit is None) != (self.fields is None)):
            return None
        return RunResults(capture=self.capture, transform=self.transform, fit=self.fit,
                          fields=self.fields, reconstructions=self.reconstructions)


@dataclass(frozen=True, eq=False)
class RunOutput:
    """One finished run from Python (:func:`nlosfw.run`): where it wrote, its configuration,
    its metrics and what its stages produced."""

    dir: Path
    """The run directory (metrics.json, report.html, figures, ...)."""
    config: Mapping[str, object]
    """The resolved configuration (as in the run's config.yaml)."""
    metrics: RunMetrics
    stages: StageResults

    def __post_init__(self) -> None:
        object.__setattr__(self, "config", _frozen_mapping(self.config))

    @property
    def results(self) -> RunResults:
        """Every stage's results; a DataError when ``stop_after`` ended the run early."""
        complete = self.stages.complete()
        if complete is None:
            raise DataError(f"{self.dir}: the run stopped after {self.metrics.run.stopped_after}; "
                            "its stages' results so far are in .stages")
        return complete

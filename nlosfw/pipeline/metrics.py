"""The one definition of ``metrics.json``: typed sections, JSON in and out, its JSON Schema.

The pipeline builds a :class:`RunMetrics`; the summary, the sweep report, the comparison
with reference numbers and the figures read one back with :meth:`RunMetrics.read`. The JSON Schema
written beside every ``metrics.json`` (``metrics.schema.json``) and the outline in
``docs/reference/metrics.md`` are generated from these classes (:mod:`nlosfw.common.typed_json`).

Every change to the layout (a key added, removed, renamed or retyped) is made here and
bumps :data:`SCHEMA_VERSION`; ``tests/pipeline/test_metrics_schema.py`` fails until it is bumped.

Two runs of the same configuration and seed on the CPU write the same metrics.json except
for the fields listed in :data:`TIMING_FIELDS` (wall-clock times and the start time); every
other artefact of a run is byte-identical (``tests/hostile/test_determinism.py``).
"""

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Final, Literal, cast

import msgspec
from msgspec import inspect as mi

from nlosfw.capture.enums import CaptureKind
from nlosfw.common.errors import DataError
from nlosfw.common.files import is_regular_file
from nlosfw.common.typed_json import (
    Absent,
    Document,
    doc,
    from_json,
    json_schema,
    outline,
    to_json,
)
from nlosfw.model.interface import FitReport
from nlosfw.pipeline.metrics_versions import metrics_as_current
from nlosfw.pipeline.nulls import Number, error_values, fit_values, with_explicit_nulls

SchemaVersion = Literal[10]
#: Version of the metrics.json layout; bump it (both lines) with every change to it, and
#: say in :mod:`nlosfw.pipeline.metrics_versions` how an older file reads as this one.
SCHEMA_VERSION: Final[SchemaVersion] = 10

#: A section's ``null_reasons``: why each of its null values is null (one line each), by
#: its key (``fitted.<name>`` for a fitted number); absent when none is
#: (:mod:`nlosfw.pipeline.nulls`).
NullReasons = Annotated[Absent[dict[str, str]], doc(
    "why each null value of this section is null, in one line, by its key (fitted.<name> "
    "for a fitted number); absent when none is", key="key")]

Status = Literal["running", "completed", "stopped", "failed", "interrupted"]
"""``running`` only while the run is in progress: metrics.json is written when it ends.
``failed`` and ``interrupted`` (SIGINT, SIGTERM) runs say where and why in ``error``."""

#: The fields of metrics.json that differ between two runs of the same configuration and
#: seed (dotted paths; ``*`` stands for any key): wall-clock times and the start time.
TIMING_FIELDS: Final = (
    "run.started",
    "timings",
    "field.*.fit.seconds",
    "field.*.predict_seconds",
    "reconstruction.sources.*.seconds",
    "reconstruction.single_frequency.*.sources.*.seconds",
)


class RunInfo(Document, frozen=True, kw_only=True):
    """What ran: the run directory, the nlosfw version, the start, the capture (a scene and
    its simulator, or a file and its format) and the plugins selected."""

    dir: str
    nlosfw_version: str
    started: Annotated[str, doc("local start time, ISO 8601 (%Y-%m-%dT%H:%M:%S%z); a timing")]
    config_hash: Annotated[str, doc("SHA-256 of the configuration without the run-control "
                                    "options (cache, limits, output.overwrite): a resumed "
                                    "sweep skips a finished run only when it matches")]
    scene: Annotated[str | None, doc("the simulated scene (null for a run from a file)")]
    simulator: Annotated[str | None, doc("its simulator (null for a run from a file)")]
    capture_file: Annotated[Absent[str], doc("the capture file read (capture.path)")] = None
    capture_format: Annotated[Absent[str], doc("the capture format that read it")] = None
    transform: str | None
    model: str | None
    imager: str | None
    stopped_after: Annotated[Absent[str], doc("the last stage that ran, when stop_after ended the "
                                              "run early")] = None


class PreprocessingStep(Document, frozen=True, kw_only=True):
    """One preprocessing step, as applied (enough to repeat it: ``capture.<option>=<value>``)."""

    option: Annotated[str, doc("the option (capture.<option>); grid: a list of wall points "
                               "arranged as the regular grid it forms")]
    value: Annotated[Any, doc("its value as the config spells it")]
    source: Annotated[Literal["option", "format", "automatic"], doc(
        "the run's options, the capture format's default, or automatic (grid)")]
    effect: Annotated[str, doc("what it did, in words")]


class CountSplittingMetrics(Document, frozen=True, kw_only=True):
    """Count splitting: every bin's count n split into Binomial(n, 1/2) (half A, which the
    models train on) and the rest (half B, which every score uses)."""

    seed: Annotated[int, doc("split.count_splitting_seed")]
    count_scale: Annotated[float, doc("photon counts per unit of H (1: a file's raw counts)")]
    counts_a: Annotated[int, doc("photon counts in half A")]
    counts_b: Annotated[int, doc("photon counts in half B")]


class CaptureMetrics(Document, frozen=True, kw_only=True):
    """The capture: where it came from, how it was preprocessed, its shape, timing and
    total signal (after preprocessing)."""

    source: Literal["simulated", "file"]
    path: Annotated[Absent[str], doc("the file read (source: file)")] = None
    format: Annotated[Absent[str], doc("the capture format that read it (source: file)")] = None
    preprocessing: Annotated[tuple[PreprocessingStep, ...], doc(
        "every step applied, in order (empty: none)")]
    simulator: Annotated[Absent[str], doc("the simulator plugin (source: simulated)")] = None
    cache_hit: Annotated[Absent[bool], doc(
        "whether the simulated capture came from the cache")] = None
    shape: Annotated[tuple[int, ...], doc("shape of the transient H (time first)")]
    kind: CaptureKind
    delta_t: Annotated[float, doc("bin width (m of optical path)")]
    t_start: Annotated[float, doc("path length of the first bin (m)")]
    total: Annotated[float, doc("sum of H")]
    noise: Annotated[Absent[Any], doc(
        "the noise the capture carries, as its scene_info records it")] = None
    count_splitting: Annotated[Absent[CountSplittingMetrics], doc(
        "count splitting (split.count_splitting): the capture above is half A")] = None


class TransformMetrics(Document, frozen=True, kw_only=True):
    """The phasor field of the capture."""

    name: str
    cache_hit: bool
    n_frequencies: int
    frequency_band: Annotated[tuple[float, float], doc("lowest and highest frequency (cycles/m)")]
    grid: Annotated[tuple[int, int], doc("wall grid (ny, nx)")]


class SplitMetrics(Document, frozen=True, kw_only=True):
    """Which samples the field models trained on (the run's ``split``)."""

    pattern: Literal["grid", "random"]
    spatial_step: Annotated[int, doc("grid: every k-th wall sample in x and y")]
    spatial_fraction: Annotated[Absent[float], doc(
        "random: the fraction of wall samples kept")] = None
    seed: Annotated[Absent[int], doc("random: the seed that drew the samples")] = None
    wall_samples: Annotated[int, doc("wall samples of the full capture")]
    train_samples: Annotated[int, doc("wall samples the models trained on (and raw images)")]
    undersampling: Annotated[float, doc("wall_samples / train_samples (4, 16, 64 for steps "
                                        "2, 4, 8)")]
    train_frequencies: int
    heldout_frequencies: int


class FitMetrics(Document, frozen=True, kw_only=True):
    """How a field model's fit went."""

    steps: int
    seconds: Annotated[float, doc("wall-clock time of the fit; a timing")]
    final_loss: float | None
    best_val_loss: float | None
    stopped_early: bool
    fitted: Annotated[Absent[dict[str, float | None]], doc(
        "numbers the fit estimated besides the model's parameters, by name (rsd_prior with "
        "background=constant: background_rms_ratio and background_max_ratio, the RMS and "
        "largest offset |b_f| over the training frequencies / the field's RMS; with "
        "temporal_response=gaussian: response_sigma_ps, the fitted jitter's standard deviation; "
        "with time_offset=true: time_offset_ps, how late the capture's signal is (ps); with "
        "fit_lobe=true: lobe_exponent, the glossy lobe's k; null where undefined)")] = None
    null_reasons: NullReasons = None

    @classmethod
    def of(cls, report: FitReport) -> "FitMetrics":
        """How a fit went, from its report (a NaN or inf loss or number null, with why)."""
        values = fit_values(report.final_loss, report.best_val_loss, report.fitted)
        return cls(steps=int(report.steps), seconds=round(report.seconds, 3),
                   final_loss=values.final_loss, best_val_loss=values.best_val_loss,
                   stopped_early=bool(report.stopped_early),
                   fitted=values.fitted or None, null_reasons=values.reasons or None)


class ErrorMetrics(Document, frozen=True, kw_only=True):
    """Complex errors of a predicted field on one set of samples (null where undefined: the
    set is empty, the true field is zero there, the prediction is exact): relative_l2 =
    |P^ - P| / |P|, nmse_db = 20 log10 of it, phase_error is magnitude-weighted (radians)."""

    relative_l2: float | None
    nmse_db: float | None
    amplitude_rmse: float | None
    relative_amplitude_rmse: float | None
    phase_error: float | None
    n_samples: int
    null_reasons: NullReasons = None

    @classmethod
    def of(cls, values: Mapping[str, Number]) -> "ErrorMetrics":
        """From one set of :func:`nlosfw.evaluation.field_metrics`'s result (each value that is
        not a finite number null, with why)."""
        checked, reasons = error_values(values)
        return cls(**checked, n_samples=int(values.get("n_samples") or 0),
                   null_reasons=reasons or None)


class HeldoutMeasurementMetrics(Document, frozen=True, kw_only=True):
    """Count splitting: the prediction at the wall points not kept against half B's measured
    field there, over the whole band, as ratios to B's power there in dB (10 log10)."""

    nmse_db: Annotated[float | None, doc("the error: sum |P^ - P_B|^2 / sum |P_B|^2")]
    floor_db: Annotated[float | None, doc(
        "the noise floor, the error of a perfect predictor: the variance B's Poisson noise "
        "adds to its field (through the transform) / sum |P_B|^2")]
    excess_db: Annotated[float | None, doc(
        "the error minus the floor (linear units, then dB): the error against B's "
        "noise-free field; null when the error is within the floor")]
    excess: Annotated[float | None, doc(
        "the error minus the floor as a ratio (may be <= 0; null where undefined)")]
    n_samples: Annotated[int, doc("held-out samples (points x frequencies)")]
    null_reasons: NullReasons = None


class SplitErrors(Document, frozen=True, kw_only=True):
    """A prediction's errors on the sets of the thesis's protocol (against half B's field
    with count splitting)."""

    heldout_pixels: Annotated[ErrorMetrics, doc("wall samples never trained on, at training "
                                                "frequencies")]
    heldout_frequencies: Annotated[ErrorMetrics, doc("every wall sample at held-out frequencies")]
    all: Annotated[ErrorMetrics, doc("every sample")]
    heldout_pixels_inside: Annotated[ErrorMetrics, doc("held-out pixels inside the training "
                                                       "grid's bounding box")]
    heldout_measurement: Annotated[Absent[HeldoutMeasurementMetrics], doc(
        "count splitting: the held-out measurement error, its noise floor and the excess "
        "(the primary score on measured data)")] = None

    @classmethod
    def of(cls, errors: Mapping[str, Mapping[str, Any]],
           heldout: HeldoutMeasurementMetrics | None = None) -> "SplitErrors":
        """From :func:`nlosfw.evaluation.field_metrics`'s result (and count splitting's score)."""
        return cls(**{name: ErrorMetrics.of(values) for name, values in errors.items()},
                   heldout_measurement=heldout)

    def by_set(self) -> dict[str, ErrorMetrics]:
        """The errors by set name, in declaration order."""
        return {name: value for name in self.__struct_fields__
                if isinstance(value := getattr(self, name), ErrorMetrics)}


class DenoisingMetrics(Document, frozen=True, kw_only=True):
    """Errors against the noise-free field (scenes with noise)."""

    noisy_relative_l2: Annotated[float | None, doc("of the noisy full field")]
    relative_l2: Annotated[float | None, doc("of the prediction")]
    gain_db: Annotated[float | None, doc("20 log10(noisy_relative_l2 / relative_l2)")]
    null_reasons: NullReasons = None


class FieldMetrics(Document, frozen=True, kw_only=True):
    """One field model of the run (``model``, ``interp`` or a ``compare`` label)."""

    plugin: str
    seed: Annotated[Absent[int], doc("the model's seed option (neural models: initialisation and "
                                     "batches)")] = None
    n_parameters: int
    training_values: Annotated[int, doc("real values trained on (2 per complex sample)")]
    parameters_per_value: float
    predict_seconds: Annotated[Absent[float], doc(
        "wall-clock time of the prediction; a timing")] = None
    fit: FitMetrics
    splits: Absent[SplitErrors] = None
    denoising: Absent[DenoisingMetrics] = None


class ImageScores(Document, frozen=True, kw_only=True):
    """A reconstruction against the full capture's (source ``true``; with count splitting
    half B's full scan, and source ``ceiling`` is half A's full scan), on amplitudes (the
    square root of the intensity) each normalised to its maximum, with scikit-image's
    PSNR and SSIM at their defaults (null where undefined, with why: PSNR of identical
    images, SSIM of images under 7 pixels a side, the depth of a dark reconstruction)."""

    rmse: Annotated[float | None, doc("of the front view: the maximum over depth")]
    psnr: Annotated[float | None, doc("dB, of the front view")]
    ssim: Annotated[float | None, doc("of the front view")]
    scale_invariant_psnr: Annotated[Absent[float | None], doc(
        "dB, of the front view times the least-squares gain that matches it to the "
        "reference's: the error once overall brightness is matched")] = None
    front_view_gain: Annotated[Absent[float | None], doc(
        "that gain (above 1: this front view is darker than the reference's, each "
        "normalised to its maximum)")] = None
    volume_psnr: Annotated[float | None, doc("dB, of the whole (z, y, x) volume")]
    volume_ssim: Annotated[float | None, doc("of the whole (z, y, x) volume")]
    depth_rmse_m: Annotated[Absent[float | None], doc(
        "RMS error (m) of the depth of each column's brightest voxel against the scene's "
        "true depth, over the pixels with a surface (scenes with ground truth; null when "
        "it cannot be computed: no surface, or a dark column there)")] = None
    seconds: Annotated[Absent[float], doc("time to reconstruct; a timing")] = None
    null_reasons: NullReasons = None


class SingleFrequencyMetrics(Document, frozen=True, kw_only=True):
    """Reconstructions from one frequency alone (as in the thesis's figures)."""

    frequency: Annotated[float, doc("cycles/m")]
    split: Literal["training", "held-out"]
    sources: Annotated[dict[str, ImageScores], doc("scores by source", key="source")]


class ReconstructionMetrics(Document, frozen=True, kw_only=True):
    """Every field imaged on the same voxels, scored against the true field's image."""

    imager: str
    reference: Literal["true"]
    depths: Annotated[tuple[float, ...], doc("depth planes (m)")]
    depth_planes: Annotated[int, doc("number of depth planes")]
    depth_spacing: Annotated[float | None, doc(
        "distance between neighbouring planes (m; null for one plane or uneven planes)")]
    sources: Annotated[dict[str, ImageScores], doc(
        "true, raw, ceiling (count splitting), interp, model and every compare label",
        key="source")]
    single_frequency: Annotated[dict[str, SingleFrequencyMetrics], doc(
        "by frequency index", key="index")]


class RunError(Document, frozen=True, kw_only=True):
    """Why a run did not finish: the stage it was in and the one-line reason."""

    stage: Annotated[str | None, doc("the stage that was running (null: before the first)")]
    message: Annotated[str, doc("the one-line error, or the signal that interrupted the run")]
    signal: Annotated[Absent[str], doc("SIGINT or SIGTERM, for an interrupted run")] = None


class Timings(Document, frozen=True, kw_only=True):
    """Seconds per stage that ran, and in total (all timings)."""

    capture: Absent[float] = None
    transform: Absent[float] = None
    fit: Absent[float] = None
    predict: Absent[float] = None
    reconstruct: Absent[float] = None
    report: Absent[float] = None
    total: Absent[float] = None


class RunMetrics(Document, frozen=True, kw_only=True):
    """The metrics of one run (``metrics.json``), nested by stage."""

    # defaults as factories: msgspec then writes them although they are the defaults
    schema_version: SchemaVersion = msgspec.field(default_factory=lambda: SCHEMA_VERSION)
    status: Status = msgspec.field(default_factory=lambda: "running")
    run: RunInfo
    capture: Absent[CaptureMetrics] = None
    transform: Absent[TransformMetrics] = None
    split: Absent[SplitMetrics] = None
    field: Annotated[Absent[dict[str, FieldMetrics]], doc(
        "by source: model, interp and every compare label", key="source")] = None
    reconstruction: Absent[ReconstructionMetrics] = None
    error: Annotated[Absent[RunError], doc(
        "where and why a failed or interrupted run ended")] = None
    timings: Timings = msgspec.field(default_factory=Timings)

    def to_json(self) -> dict[str, object]:
        """The JSON object of metrics.json: every value ``null_reasons`` explains is there,
        as null (one that may be absent, such as ``depth_rmse_m``, too)."""
        return with_explicit_nulls(to_json(self))

    def dumps(self) -> str:
        """The text of metrics.json (json's layout: indented, ASCII, floats as repr)."""
        return json.dumps(self.to_json(), indent=2) + "\n"

    @classmethod
    def from_json(cls, data: object, where: str = "") -> "RunMetrics":
        """Metrics from the JSON object of a metrics.json of this :data:`SCHEMA_VERSION`, or
        of an older one that still reads as it
        (:func:`~nlosfw.pipeline.metrics_versions.metrics_as_current`)."""
        return from_json(cls, metrics_as_current(data, SCHEMA_VERSION, where), where)

    @classmethod
    def read(cls, path: Path) -> "RunMetrics":
        """Read a metrics.json; a one-line :class:`DataError` names the file and the problem."""
        if Path(path).exists() and not is_regular_file(path):
            raise DataError(f"{path}: not a regular file (a FIFO, a device or a directory); "
                            "it is not read")
        try:
            data = msgspec.json.decode(Path(path).read_bytes())
        except (OSError, msgspec.DecodeError) as err:
            raise DataError(f"{path}: unreadable ({err})") from None
        return cls.from_json(data, where=str(path))

    def field_entry(self, source: str) -> FieldMetrics | None:
        """The metrics of one field model (``model``, ``interp``, ...), if it was fitted."""
        return (self.field or {}).get(source)

    def image_scores(self, source: str) -> ImageScores | None:
        """The reconstruction scores of one source, if it was imaged."""
        return None if self.reconstruction is None else self.reconstruction.sources.get(source)


def without_timings(data: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of a metrics.json object without the :data:`TIMING_FIELDS`: equal for two runs
    of the same configuration and seed on the CPU."""

    def drop(node: Any, path: list[str]) -> Any:
        if not isinstance(node, Mapping):
            return node
        head, rest = path[0], path[1:]
        keys = list(node) if head == "*" else [head]
        out = dict(node)
        for key in keys:
            if key in out:
                if rest:
                    out[key] = drop(out[key], rest)
                else:
                    del out[key]
        return out

    result: Any = json.loads(json.dumps(data))
    for dotted in TIMING_FIELDS:
        result = drop(result, dotted.split("."))
    return dict(result)


def metrics_schema() -> dict[str, Any]:
    """The JSON Schema of metrics.json (written as metrics.schema.json beside it)."""
    return json_schema(RunMetrics, title=f"nlosfw metrics.json, schema version {SCHEMA_VERSION}",
                       schema_id=f"urn:nlosfw:metrics:{SCHEMA_VERSION}")


def metrics_schema_text() -> str:
    """The text of metrics.schema.json."""
    return json.dumps(metrics_schema(), indent=2) + "\n"


def metrics_outline() -> str:
    """The compact outline of metrics.json shown in docs/reference/metrics.md."""
    return outline(RunMetrics)


def _numbers(struct: type[msgspec.Struct], prefix: str = "") -> tuple[str, ...]:
    """The dotted paths of the numbers in ``struct`` and the structs it holds."""
    out: list[str] = []
    for entry in cast(mi.StructType, mi.type_info(struct)).fields:
        kind = entry.type.type if isinstance(entry.type, mi.Metadata) else entry.type
        kinds = kind.types if isinstance(kind, mi.UnionType) else (kind,)
        nested = [k for k in kinds if isinstance(k, mi.StructType)]
        if nested:
            out += _numbers(nested[0].cls, f"{prefix}{entry.name}.")
        elif any(isinstance(k, (mi.IntType, mi.FloatType)) for k in kinds):
            out.append(f"{prefix}{entry.name}")
    return tuple(out)


#: The numbers of ``field.<source>`` by dotted path (what published numbers compare with).
FIELD_NUMBERS: Final = _numbers(FieldMetrics)

"""The one definition of ``metrics.json``: typed sections, JSON in and out, its JSON Schema.

The pipeline builds a :class:`RunMetrics`; the summary, the sweep report, the thesis
comparison and the figures read one back with :meth:`RunMetrics.read`. The JSON Schema
written beside every ``metrics.json`` (``metrics.schema.json``) and the outline in the
README are generated from these classes (:mod:`nlosfw.common.typed_json`).

Every change to the layout (a key added, removed, renamed or retyped) is made here and
bumps :data:`SCHEMA_VERSION`; ``tests/test_metrics_schema.py`` fails until it is bumped.

Two runs of the same configuration and seed on the CPU write the same metrics.json except
for the fields listed in :data:`TIMING_FIELDS` (wall-clock times and the start time); every
other artefact of a run is byte-identical (``tests/hostile/test_determinism.py``).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

from nlosfw.capture.enums import CaptureKind
from nlosfw.common.errors import DataError
from nlosfw.common.typed_json import documented, from_json, json_schema, optional, outline, to_json
from nlosfw.model.interface import FitReport

SchemaVersion = Literal[6]
#: Version of the metrics.json layout; bump it (both lines) with every change to it.
SCHEMA_VERSION: Final[SchemaVersion] = 6

#: Older versions :meth:`RunMetrics.from_json` still reads: each later version only added
#: optional keys (6: count splitting, ``capture.thinning`` and
#: ``field.*.splits.heldout_measurement``), so such a file reads as this version.
READABLE_VERSIONS: Final = (5, 6)

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


@dataclass(frozen=True, kw_only=True)
class RunInfo:
    """What ran: the run directory, the nlosfw version, the start, the capture (a scene and
    its simulator, or a file and its format) and the plugins selected."""

    dir: str
    nlosfw_version: str
    started: str = documented("local start time, ISO 8601 (%Y-%m-%dT%H:%M:%S%z); a timing")
    config_hash: str = documented("SHA-256 of the configuration without the run-control "
                                  "options (cache, limits, output.overwrite): a resumed "
                                  "sweep skips a finished run only when it matches")
    scene: str | None = documented("the simulated scene (null for a run from a file)")
    simulator: str | None = documented("its simulator (null for a run from a file)")
    capture_file: str | None = optional("the capture file read (capture.path)")
    capture_format: str | None = optional("the capture format that read it")
    transform: str | None
    model: str | None
    imager: str | None
    stopped_after: str | None = optional("the last stage that ran, when stop_after ended the "
                                         "run early")


@dataclass(frozen=True, kw_only=True)
class PreprocessingStep:
    """One preprocessing step, as applied (enough to repeat it: ``capture.<option>=<value>``)."""

    option: str = documented("the option (capture.<option>); grid: a list of wall points "
                             "arranged as the regular grid it forms")
    value: Any = documented("its value as the config spells it")
    source: Literal["option", "format", "automatic"] = documented(
        "the run's options, the capture format's default, or automatic (grid)")
    effect: str = documented("what it did, in words")


@dataclass(frozen=True, kw_only=True)
class CaptureMetrics:
    """The capture: where it came from, how it was preprocessed, its shape, timing and
    total signal (after preprocessing)."""

    source: Literal["simulated", "file"]
    path: str | None = optional("the file read (source: file)")
    format: str | None = optional("the capture format that read it (source: file)")
    preprocessing: tuple[PreprocessingStep, ...] = documented(
        "every step applied, in order (empty: none)")
    simulator: str | None = optional("the simulator plugin (source: simulated)")
    cache_hit: bool | None = optional("whether the simulated capture came from the cache")
    shape: tuple[int, ...] = documented("shape of the transient H (time first)")
    kind: CaptureKind
    delta_t: float = documented("bin width (m of optical path)")
    t_start: float = documented("path length of the first bin (m)")
    total: float = documented("sum of H")
    noise: Any = optional("the noise the capture carries, as its scene_info records it")
    thinning: ThinningMetrics | None = optional("count splitting (split.thinning): the "
                                                "capture above is half A")


@dataclass(frozen=True, kw_only=True)
class ThinningMetrics:
    """Count splitting: every bin's count n split into Binomial(n, 1/2) (half A, which the
    models train on) and the rest (half B, which every score uses)."""

    seed: int = documented("split.thinning_seed")
    count_scale: float = documented("photon counts per unit of H (1: a file's raw counts)")
    counts_a: int = documented("photon counts in half A")
    counts_b: int = documented("photon counts in half B")


@dataclass(frozen=True, kw_only=True)
class TransformMetrics:
    """The phasor field of the capture."""

    name: str
    cache_hit: bool
    n_frequencies: int
    frequency_band: tuple[float, float] = documented("lowest and highest frequency (cycles/m)")
    grid: tuple[int, int] = documented("wall grid (ny, nx)")


@dataclass(frozen=True, kw_only=True)
class SplitMetrics:
    """Which samples the field models trained on (the run's ``split``)."""

    pattern: Literal["grid", "random"]
    spatial_step: int = documented("grid: every k-th wall sample in x and y")
    spatial_fraction: float | None = optional("random: the fraction of wall samples kept")
    seed: int | None = optional("random: the seed that drew the samples")
    wall_samples: int = documented("wall samples of the full capture")
    train_samples: int = documented("wall samples the models trained on (and raw images)")
    undersampling: float = documented("wall_samples / train_samples (4, 16, 64 for steps "
                                      "2, 4, 8)")
    train_frequencies: int
    heldout_frequencies: int


@dataclass(frozen=True, kw_only=True)
class FitMetrics:
    """How a field model's fit went."""

    steps: int
    seconds: float = documented("wall-clock time of the fit; a timing")
    final_loss: float | None
    best_val_loss: float | None
    stopped_early: bool

    @classmethod
    def of(cls, report: FitReport) -> FitMetrics:
        return cls(steps=int(report.steps), seconds=round(report.seconds, 3),
                   final_loss=report.final_loss, best_val_loss=report.best_val_loss,
                   stopped_early=bool(report.stopped_early))


@dataclass(frozen=True, kw_only=True)
class ErrorMetrics:
    """Complex errors of a predicted field on one set of samples (null when the set is
    empty): relative_l2 = |P^ - P| / |P|, nmse_db = 20 log10 of it, phase_error is
    magnitude-weighted (radians)."""

    relative_l2: float | None
    nmse_db: float | None
    amplitude_rmse: float | None
    relative_amplitude_rmse: float | None
    phase_error: float | None
    n_samples: int


@dataclass(frozen=True, kw_only=True)
class HeldoutMeasurementMetrics:
    """Count splitting: the prediction at the wall points not kept against half B's measured
    field there, over the whole band, as ratios to B's power there in dB (10 log10)."""

    nmse_db: float | None = documented("the error: sum |P^ - P_B|^2 / sum |P_B|^2")
    floor_db: float | None = documented(
        "the noise floor, the error of a perfect predictor: the variance B's Poisson noise "
        "adds to its field (through the transform) / sum |P_B|^2")
    excess_db: float | None = documented(
        "the error minus the floor (linear units, then dB): the error against B's "
        "noise-free field; null when the error is within the floor")
    excess: float = documented("the error minus the floor as a ratio (may be <= 0)")
    n_samples: int = documented("held-out samples (points x frequencies)")


@dataclass(frozen=True, kw_only=True)
class SplitErrors:
    """A prediction's errors on the sets of the thesis's protocol (against half B's field
    with count splitting)."""

    heldout_pixels: ErrorMetrics = documented("wall samples never trained on, at training "
                                              "frequencies")
    heldout_frequencies: ErrorMetrics = documented("every wall sample at held-out frequencies")
    all: ErrorMetrics = documented("every sample")
    heldout_pixels_inside: ErrorMetrics = documented("held-out pixels inside the training "
                                                     "grid's bounding box")
    heldout_measurement: HeldoutMeasurementMetrics | None = optional(
        "count splitting: the held-out measurement error, its noise floor and the excess "
        "(the primary score on measured data)")

    @classmethod
    def of(cls, errors: Mapping[str, Mapping[str, Any]],
           heldout: HeldoutMeasurementMetrics | None = None) -> SplitErrors:
        """From :func:`nlosfw.model.field_metrics`'s result (and count splitting's score)."""
        return cls(**{name: ErrorMetrics(**values) for name, values in errors.items()},
                   heldout_measurement=heldout)

    def by_set(self) -> dict[str, ErrorMetrics]:
        """The errors by set name, in declaration order."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if isinstance(getattr(self, f.name), ErrorMetrics)}


@dataclass(frozen=True, kw_only=True)
class DenoisingMetrics:
    """Errors against the noise-free field (scenes with noise)."""

    noisy_relative_l2: float | None = documented("of the noisy full field")
    relative_l2: float | None = documented("of the prediction")
    gain_db: float | None = documented("20 log10(noisy_relative_l2 / relative_l2)")


@dataclass(frozen=True, kw_only=True)
class FieldMetrics:
    """One field model of the run (``model``, ``interp`` or a ``compare`` label)."""

    plugin: str
    seed: int | None = optional("the model's seed option (neural models: initialisation and "
                                "batches)")
    n_parameters: int
    training_values: int = documented("real values trained on (2 per complex sample)")
    parameters_per_value: float
    predict_seconds: float | None = optional("wall-clock time of the prediction; a timing")
    fit: FitMetrics
    splits: SplitErrors | None = optional()
    denoising: DenoisingMetrics | None = optional()


@dataclass(frozen=True, kw_only=True)
class ImageScores:
    """A reconstruction against the full capture's (source ``true``; with count splitting
    half B's full scan, and source ``ceiling`` is half A's full scan), on amplitudes (the
    square root of the intensity) each normalised to its maximum, with scikit-image's
    PSNR and SSIM at their defaults (null where undefined: PSNR of identical images,
    SSIM of images under 7 pixels a side)."""

    rmse: float | None = documented("of the front view: the maximum over depth")
    psnr: float | None = documented("dB, of the front view")
    ssim: float | None = documented("of the front view")
    volume_psnr: float | None = documented("dB, of the whole (z, y, x) volume")
    volume_ssim: float | None = documented("of the whole (z, y, x) volume")
    depth_rmse_m: float | None = optional(
        "RMS error (m) of the depth of each column's brightest voxel against the scene's "
        "true depth, over the pixels with a surface (scenes with ground truth)")
    seconds: float | None = optional("time to reconstruct; a timing")


@dataclass(frozen=True, kw_only=True)
class SingleFrequencyMetrics:
    """Reconstructions from one frequency alone (as in the thesis's figures)."""

    frequency: float = documented("cycles/m")
    split: Literal["training", "held-out"]
    sources: dict[str, ImageScores] = documented("scores by source", key="source")


@dataclass(frozen=True, kw_only=True)
class ReconstructionMetrics:
    """Every field imaged on the same voxels, scored against the true field's image."""

    imager: str
    reference: Literal["true"]
    depths: tuple[float, ...] = documented("depth planes (m)")
    depth_planes: int = documented("number of depth planes")
    depth_spacing: float | None = documented(
        "distance between neighbouring planes (m; null for one plane or uneven planes)")
    sources: dict[str, ImageScores] = documented("true, raw, ceiling (count splitting), "
                                                 "interp, model and every compare label",
                                                 key="source")
    single_frequency: dict[str, SingleFrequencyMetrics] = documented(
        "by frequency index", key="index")


@dataclass(frozen=True, kw_only=True)
class RunError:
    """Why a run did not finish: the stage it was in and the one-line reason."""

    stage: str | None = documented("the stage that was running (null: before the first)")
    message: str = documented("the one-line error, or the signal that interrupted the run")
    signal: str | None = optional("SIGINT or SIGTERM, for an interrupted run")


@dataclass(frozen=True, kw_only=True)
class Timings:
    """Seconds per stage that ran, and in total (all timings)."""

    capture: float | None = optional()
    transform: float | None = optional()
    fit: float | None = optional()
    predict: float | None = optional()
    reconstruct: float | None = optional()
    report: float | None = optional()
    total: float | None = optional()


@dataclass(frozen=True, kw_only=True)
class RunMetrics:
    """The metrics of one run (``metrics.json``), nested by stage."""

    schema_version: SchemaVersion = SCHEMA_VERSION
    status: Status = "running"
    run: RunInfo
    capture: CaptureMetrics | None = optional()
    transform: TransformMetrics | None = optional()
    split: SplitMetrics | None = optional()
    field: dict[str, FieldMetrics] | None = optional(
        "by source: model, interp and every compare label", key="source")
    reconstruction: ReconstructionMetrics | None = optional()
    error: RunError | None = optional("where and why a failed or interrupted run ended")
    timings: Timings = dataclasses.field(default_factory=Timings)

    def to_json(self) -> dict[str, Any]:
        """The JSON object of metrics.json."""
        return to_json(self)

    def dumps(self) -> str:
        """The text of metrics.json."""
        return json.dumps(self.to_json(), indent=2) + "\n"

    @classmethod
    def from_json(cls, data: Any, where: str = "") -> RunMetrics:
        """Metrics from the JSON object of a metrics.json of this :data:`SCHEMA_VERSION`."""
        version = data.get("schema_version") if isinstance(data, dict) else None
        if isinstance(data, dict) and version not in READABLE_VERSIONS:
            raise DataError(f"{where + ': ' if where else ''}schema_version is {version!r}; this "
                            f"nlosfw reads versions {', '.join(map(str, READABLE_VERSIONS))} "
                            "(written by another nlosfw version: rerun it, or read it with the "
                            "version that wrote it)")
        if isinstance(data, dict) and version != SCHEMA_VERSION:
            data = {**data, "schema_version": SCHEMA_VERSION}  # later versions only add keys
        return from_json(cls, data, where)

    @classmethod
    def read(cls, path: Path) -> RunMetrics:
        """Read a metrics.json; a one-line :class:`DataError` names the file and the problem."""
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as err:
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
    """The compact outline of metrics.json shown in the README."""
    return outline(RunMetrics)

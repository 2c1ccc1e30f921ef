"""The run options of ``python -m nlosfw`` outside the plugin and scene groups.

These are the top-level keys of ``conf/config.yaml``. :class:`RunConfig` adds the
selected scene and plugins to them: it is the schema Hydra composes ``config.yaml``
against, and :func:`run_settings` validates the settings by name, type and range like
every other config.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from omegaconf import MISSING

from nlosfw.capture.source import CaptureSource
from nlosfw.common.config import Choice, config_from_mapping, require, require_seed
from nlosfw.common.schema import is_schema_node
from nlosfw.evaluation.splits import SpatialPattern, SpatialSampling, SpectralSplit
from nlosfw.pipeline.metrics import FIELD_NUMBERS
from nlosfw.simulate.scene import Scene

#: The config groups that select a scene or a plugin (plus presets and acquisitions).
SELECTOR_GROUPS = ("scene", "simulator", "transform", "model", "imager", "experiment",
                   "acquisition", "sampling")

#: The selector groups whose choice may be null (nothing selected).
OPTIONAL_GROUPS = ("experiment", "acquisition", "sampling")

#: The ``model`` choice that fits no field model: the run images the capture alone (no
#: split, no fit, no prediction, no field scores); ``python -m nlosfw image FILE`` selects it.
NO_MODEL = "none"

#: Pipeline stages in order; ``stop_after`` accepts any of them (``simulate`` = ``capture``).
STAGES = ("capture", "transform", "fit", "predict", "reconstruct", "report")


class StopAfter(Choice):
    """The last stage a run performs (``simulate`` is ``capture``)."""

    capture = "capture"
    simulate = "simulate"
    transform = "transform"
    fit = "fit"
    predict = "predict"
    reconstruct = "reconstruct"


@dataclass(frozen=True)
class SplitSettings:
    """Which samples the field model trains on (thesis: 32x32 of 64x64, 90% of frequencies)."""

    renamed_options: ClassVar[Mapping[str, str]] = {
        "thinning": "count_splitting", "thinning_seed": "count_splitting_seed"}

    spatial_step: int = 2
    """Keep every k-th wall sample in x and y for training (pattern grid)."""
    pattern: SpatialPattern = SpatialPattern.grid
    """``grid``: every ``spatial_step``-th sample; ``random``: a random ``spatial_fraction``
    of the wall samples."""
    spatial_fraction: float | None = None
    """Pattern random: the fraction of wall samples kept; null: 1 / spatial_step^2 (as many
    as the grid pattern keeps)."""
    seed: int = 0
    """Pattern random: the seed that draws the samples."""
    spectral: SpectralSplit = SpectralSplit.interleaved
    """Hold out every n-th frequency (interpolation), the highest ones (extrapolation), or none."""
    spectral_fraction: float = 0.1
    """The fraction of the frequencies held out (``interleaved``: every 1/fraction-th)."""
    count_splitting: bool = False
    """Count splitting: split every bin's photon count n into Binomial(n, 1/2) (capture A)
    and the rest (B), two independent Poisson captures of half the exposure; the models
    train on A's kept wall points, every score uses B (the held-out measurement error and
    its noise floor; reconstructions against B's full scan, with A's full scan as the
    ceiling). Needs raw integer counts (no capture.background); approximate under dead
    time and pile-up; assumes equal dwell per scan point."""
    count_splitting_seed: int = 0
    """The seed of the binomial split (count splitting)."""

    def __post_init__(self) -> None:
        require_seed(self.seed, "seed")
        require_seed(self.count_splitting_seed, "count_splitting_seed")
        require(self.spatial_step >= 1, "spatial_step", f"must be >= 1, got {self.spatial_step}")
        require(self.spatial_fraction is None or 0 < self.spatial_fraction <= 1,
                "spatial_fraction", f"must be in (0, 1] or null, got {self.spatial_fraction}")
        require(self.spatial_fraction is None or self.pattern == SpatialPattern.random,
                "spatial_fraction", "applies to pattern random only (the grid pattern keeps "
                "every spatial_step-th sample); set split.pattern=random or leave it null")
        require(0 < self.spectral_fraction < 1, "spectral_fraction",
                f"must be in (0, 1), got {self.spectral_fraction}")

    @property
    def sampling(self) -> SpatialSampling:
        """The spatial pattern as the protocol takes it."""
        return SpatialSampling(pattern=self.pattern, step=self.spatial_step,
                               fraction=self.spatial_fraction, seed=self.seed)


@dataclass(frozen=True)
class ReconstructionSettings:
    """The voxels imaged from every field."""

    depths: tuple[float, ...] = ()
    """[m] Depth planes; empty: planes spanning ``depth_range`` or, when it is not set, the
    scene's ground truth or the depths the capture's time profile holds signal at."""
    depth_range: tuple[float, float] | None = None
    """[m] Near and far depth of the planes when ``depths`` is empty."""
    n_depths: int | None = None
    """Number of planes; None (default): a quarter of the shortest wavelength of the band
    apart in the volume, 1/(4 m f_max) with m = 2 for confocal captures, else 1."""
    single_frequency_images: int = 2
    """How many single-frequency images (as in the thesis figures) to add per field."""
    histogram_reference: bool | None = None
    """Also image the capture's histograms at their native bin width (every DFT bin, as the
    authors' code images them) with the run's time-domain imager on the same planes: the
    reference picture beside the sources in report.html, never scored. null: for a capture
    file imaged by lct, fk or fbp; true: also for a simulated capture (needs such an
    imager); false: never. Skipped, with the reason in the log, when its estimated memory
    exceeds what is available (limits.allow_large: made anyway)."""
    pick_imager: bool = False
    """Image with the imager picked for the capture's geometry (nlosfw.image.choice: lct for
    a confocal scan on a regular grid, else fft) instead of ``imager``, and no reference
    picture unless ``histogram_reference`` is true; the log says which and why.
    ``python -m nlosfw image FILE`` sets it unless an ``imager`` option is given."""

    def __post_init__(self) -> None:
        require(all(d > 0 for d in self.depths), "depths", "every depth must be > 0 (in front "
                "of the wall)")
        require(self.n_depths is None or self.n_depths >= 1, "n_depths",
                f"must be >= 1 or null (automatic), got {self.n_depths}")
        if self.depth_range is not None:
            lo, hi = self.depth_range
            require(0 < lo < hi, "depth_range", f"must satisfy 0 < near < far, got "
                    f"{self.depth_range}")
        require(self.single_frequency_images >= 0, "single_frequency_images", "must be >= 0")


#: The resolutions a figure may have (dots per inch): a figure of 10 x 8 inches at 1200 dpi
#: is 115 million pixels already; beyond, drawing it ends in an out-of-memory error.
MIN_DPI, MAX_DPI = 30, 1200


@dataclass(frozen=True)
class FigureSettings:
    """The PNG figures of a run (``figures/``)."""

    enabled: bool = True
    """Draw the figures (false: metrics and files only)."""
    dpi: int = 110
    """Resolution of the PNG files (dots per inch, 30 to 1200)."""

    def __post_init__(self) -> None:
        require(MIN_DPI <= self.dpi <= MAX_DPI, "dpi",
                f"must be {MIN_DPI} to {MAX_DPI} (dots per inch), got {self.dpi}")


@dataclass(frozen=True)
class CacheSettings:
    """Captures and phasor fields are cached by a hash of the config that produced them."""

    enabled: bool = True
    """Read and write the cache (false: compute everything again)."""
    dir: str = "~/.cache/nlosfw"
    """Where the cache lives (``$NLOSFW_CACHE_DIR`` when set)."""
    max_gb: float | None = 20.0
    """[GB] Size limit: beyond it the least recently used entries are evicted (never one a
    running process is using); null: no limit."""

    def __post_init__(self) -> None:
        require(self.max_gb is None or self.max_gb >= 0, "max_gb",
                f"must be >= 0 (GB) or null, got {self.max_gb}")


class Artefact(Choice):
    """The large files a run can keep (``output.keep``); metrics, config, log and figures are
    always written."""

    capture = "capture"
    """``capture.hdf5``: the transient (y-tal's layout)."""
    phasor_field = "phasor_field"
    """``phasor_field.hdf5``: the phasor field of the capture."""
    fields = "fields"
    """``fields/<source>.hdf5``: every field that is imaged."""
    model = "model"
    """``field_model.npz``: the trained field model."""
    reconstructions = "reconstructions"
    """``reconstructions/<source>.hdf5``: the reconstruction of every field."""


@dataclass(frozen=True)
class OutputSettings:
    """What a run writes besides its metrics, config, log and figures."""

    keep: tuple[Artefact, ...] = (Artefact.capture, Artefact.model)
    """The large files to write: by default the capture (the run's input, slow to simulate
    with a ray tracer) and the trained model (slow to train); the phasor field, the imaged
    fields and the reconstructions follow from them quickly and are left out."""
    compression: int = 4
    """gzip level (0-9) for the transient in capture.hdf5."""
    overwrite: bool = False
    """Replace an earlier run's files in the run directory (only files that run wrote);
    without it a directory holding a run is refused."""

    def __post_init__(self) -> None:
        require(0 <= self.compression <= 9, "compression", f"must be 0-9, got {self.compression}")
        require(len(set(self.keep)) == len(self.keep), "keep",
                f"lists an artefact twice: {[str(a) for a in self.keep]}")


@dataclass(frozen=True)
class LimitSettings:
    """Safety limits checked before a run starts."""

    allow_large: bool = False
    """Run even when the memory the configuration needs (estimated before anything is
    allocated) exceeds the memory available."""


@dataclass(frozen=True)
class PublishedTable:
    """Published numbers a run is compared with: one table of one source (a paper's, a
    thesis's), reported next to the run's own in ``published_numbers.md`` and in a sweep's
    ``report.md``."""

    title: str = ""
    """Where the numbers were published and what they show (the table's heading)."""
    note: str = ""
    """What a reader comparing them should know (printed under the table)."""
    rows: dict[str, dict[str, Any]] = field(default_factory=dict)
    """By field-model source (``model``, ``interp`` or a ``compare`` label): the row's
    ``label``, and each published number where metrics.json's ``field.<source>`` holds
    the run's own, in its units (``n_parameters``, ``training_values``,
    ``parameters_per_value``, ``fit: {final_loss, seconds, steps}``, ...)."""

    def __post_init__(self) -> None:
        for source, row in self.rows.items():
            for path, value in row_numbers(row):
                require(path in FIELD_NUMBERS, f"rows.{source}.{path}",
                        "names no number of metrics.json's field.<source>; valid: "
                        + ", ".join(FIELD_NUMBERS))
                require(isinstance(value, (int, float)) and not isinstance(value, bool),
                        f"rows.{source}.{path}", f"must be a number, got {value!r}")


def row_numbers(row: Mapping[str, object], prefix: str = "") -> list[tuple[str, object]]:
    """(dotted path, value) of every published number of a :class:`PublishedTable` row, in
    their order (its ``label`` left out)."""
    out: list[tuple[str, object]] = []
    for key, value in row.items():
        path = f"{prefix}{key}"
        if path == "label":
            continue
        if isinstance(value, Mapping):
            out += row_numbers(value, f"{path}.")
        else:
            out.append((path, value))
    return out


@dataclass(frozen=True)
class RunSettings:
    """Everything in a run's config except the selected scene and plugins."""

    renamed_options: ClassVar[Mapping[str, str]] = {"thesis": "published"}

    stop_after: StopAfter | None = None
    """The last stage to run (null: every stage)."""
    capture: CaptureSource = field(default_factory=CaptureSource)
    """The capture: a file, or the scene simulated."""
    split: SplitSettings = field(default_factory=SplitSettings)
    """Which wall samples and frequencies the field models train on."""
    reconstruction: ReconstructionSettings = field(default_factory=ReconstructionSettings)
    """The voxels every field is imaged on."""
    figures: FigureSettings = field(default_factory=FigureSettings)
    """The PNG figures."""
    cache: CacheSettings = field(default_factory=CacheSettings)
    """The cache of captures and phasor fields."""
    output: OutputSettings = field(default_factory=OutputSettings)
    """Which large files the run writes, and whether it may replace an earlier run's."""
    limits: LimitSettings = field(default_factory=LimitSettings)
    """Safety limits checked before the run starts."""
    compare: dict[str, dict[str, Any]] = field(default_factory=dict)
    """More field models fitted and imaged beside ``model`` and interp: label -> options with
    the plugin ``name`` (e.g. ``{pe: {name: pe_torch, steps: 500}}``)."""
    published: dict[str, PublishedTable] = field(default_factory=dict)
    """Published numbers to compare the run with, by table name (e.g. ``thesis_table_5_1``):
    each a :class:`PublishedTable`."""

    def __post_init__(self) -> None:
        require(not (self.split.count_splitting and self.capture.background),
                "split.count_splitting", "count splitting needs raw photon counts; a background "
                "subtraction (capture.background) makes them non-integer: drop one of the two")
        require(not (self.split.count_splitting and self.capture.pileup_pulses),
                "split.count_splitting",
                "count splitting needs raw photon counts; the pile-up correction "
                "(capture.pileup_pulses) turns them into estimates: drop one of the two")
        reserved = {"true", "raw", "model", "interp", "ceiling"}
        for label, options in self.compare.items():
            require(label not in reserved and label.isidentifier(), f"compare.{label}",
                    f"labels must be identifiers other than {', '.join(sorted(reserved))}")
            require(isinstance(options, dict) and bool(options.get("name")),
                    f"compare.{label}", "needs the plugin name: {name: <model plugin>, ...}")
        fitted = {"model", "interp", *self.compare}
        for name, table in self.published.items():
            for source in table.rows:
                require(source in fitted, f"published.{name}.rows.{source}",
                        f"names no field model of the run; valid: {', '.join(sorted(fitted))}")

    @property
    def last_stage(self) -> str:
        if self.stop_after is None:
            return STAGES[-1]
        return "capture" if self.stop_after == "simulate" else str(self.stop_after)

    def runs(self, stage: str) -> bool:
        """Whether ``stage`` runs given ``stop_after``."""
        return STAGES.index(stage) <= STAGES.index(self.last_stage)

    @property
    def input_files(self) -> dict[str, str]:
        """The files the run reads besides its configuration, by option (those set)."""
        files = {"capture.path": self.capture.path,
                 "capture.background": self.capture.background,
                 "capture.tofgrid": self.capture.tofgrid}
        return {option: path for option, path in files.items() if path}


@dataclass(frozen=True)
class RunConfig(RunSettings):
    """The schema of a run's whole config: the settings, the scene and one plugin per kind.

    Only Hydra uses it (as the first entry of ``config.yaml``'s defaults list): each plugin
    group's entry brings its own schema, the plugin's config class.
    """

    scene: Scene = MISSING
    simulator: Any = MISSING
    transform: Any = MISSING
    model: Any = MISSING
    imager: Any = MISSING


def run_settings(cfg: Any) -> RunSettings:
    """The validated settings of a run's config (the node Hydra composed, or a mapping)."""
    if not is_schema_node(cfg, RunSettings):
        cfg = {k: v for k, v in dict(cfg).items() if k not in SELECTOR_GROUPS}
    return config_from_mapping(RunSettings, cfg, "")

"""The options of the physics-constrained fit ``rsd_prior`` (:mod:`nlosfw.model.physics.prior`).

:class:`PriorOptions` holds them without ``seed`` and ``device``, with the options of one
concern grouped (``depth``, ``lobe``, ``response``, ``counts``: ``model.depth.range=[0.4,
0.6]`` on the command line); :class:`RSDPriorConfig` is ``rsd_prior``'s config (them and
``seed``); the hybrids hold a :class:`PriorOptions` as their group ``prior``. The flat
names these options had before (``depth_range``, ``fit_lobe``, ...) are refused in one line
that gives the new one (``renamed_options``, read by the config checks), and read from
model files written before (:func:`nlosfw.common.config.with_current_names`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import ClassVar

from nlosfw.common.config import require, require_threads
from nlosfw.common.errors import ConfigError
from nlosfw.image.fft import Precision
from nlosfw.model.interface import FieldModelConfig
from nlosfw.model.physics.background import Background
from nlosfw.model.physics.counts import CountsStop
from nlosfw.model.physics.likelihood import Likelihood
from nlosfw.model.physics.operator import Amplitude
from nlosfw.model.physics.response import TemporalResponse


@dataclass(frozen=True)
class DepthOptions:
    """Where the voxel planes lie (``depth.*``): given, or found by a quick coarse fit."""

    range: tuple[float, ...] = ()
    """[m] Near and far depth of the voxel planes; empty: estimated from the data."""
    step: float | None = None
    """[m] Distance between voxel planes; default a fifth of the shortest wavelength."""
    threshold: float = 0.1
    """Automatic depth range: keep the planes where the coarse fit's largest contribution
    reaches this fraction of the overall largest."""
    iterations: int = 40
    """Automatic depth range: FISTA iterations of the coarse fit."""
    margin: float = 0.05
    """Automatic depth range: metres added before and after the kept planes."""

    def __post_init__(self) -> None:
        require(len(self.range) in (0, 2), "range",
                f"must be empty (automatic) or [near, far], got {list(self.range)}")
        if self.range:
            near, far = self.range
            require(0 < near <= far, "range",
                    f"must satisfy 0 < near <= far (m), got {list(self.range)}")
        require(self.step is None or self.step > 0, "step",
                f"must be > 0 m or null, got {self.step}")
        require(0 < self.threshold <= 1, "threshold",
                f"must be in (0, 1], got {self.threshold}")
        require(self.iterations >= 1, "iterations", f"must be >= 1, got {self.iterations}")
        require(self.margin >= 0, "margin", f"must be >= 0 m, got {self.margin}")


@dataclass(frozen=True)
class LobeOptions:
    """The glossy lobe of the voxels' reflectance (``lobe.*``)."""

    exponent: float = 0.0
    """Exponent k of a glossy lobe about the voxels' normal, cos^k (lambertian amplitude
    only; 0: Lambertian)."""
    fit: bool = False
    """Fit k jointly with the albedo over [0, ``max``] instead
    (:mod:`nlosfw.model.physics.lobe`)."""
    max: float = 20.0
    """``fit``: the largest k searched."""
    tolerance: float = 0.25
    """``fit``: the search stops when k is known to within this."""

    def __post_init__(self) -> None:
        require(self.exponent >= 0, "exponent",
                f"must be >= 0 (0: Lambertian), got {self.exponent}")
        require(not (self.fit and self.exponent), "exponent",
                "is fitted with lobe.fit: leave it 0, or set lobe.fit false to fix it")
        require(self.max > 0, "max", f"must be > 0, got {self.max}")
        require(self.tolerance > 0, "tolerance", f"must be > 0, got {self.tolerance}")


@dataclass(frozen=True)
class ResponseOptions:
    """The system's temporal response, fitted jointly (``response.*``;
    :mod:`nlosfw.model.physics.response`)."""

    temporal: TemporalResponse = TemporalResponse.none
    """none, or gaussian (timing jitter, the gain exp(-(2 pi f sigma)^2 / 2))."""
    time_offset: bool = False
    """Fit the capture's time-origin offset tau (the phase ramp exp(-2 pi i f tau))."""
    rounds: int = 5
    """Rounds of the response search (with a response term on): each tries every fitted term
    either side of its value, the albedo fitted again each time (a quarter of
    ``iterations``), with steps halving; a round costs about one to two fits."""

    def __post_init__(self) -> None:
        require(isinstance(self.time_offset, bool), "time_offset",
                f"must be true or false, got {self.time_offset!r}")
        require(self.rounds >= 1, "rounds", f"must be >= 1, got {self.rounds}")


@dataclass(frozen=True)
class CountsOptions:
    """``likelihood: poisson_counts``: the fit on the photon counts (``counts.*``;
    :mod:`nlosfw.model.physics.counts`)."""

    iterations: int = 100
    """The most EM iterations on the counts."""
    stop: CountsStop = CountsStop.likelihood
    """When EM stops. likelihood: the counts are split binomially (``seed``) into two
    independent halves, EM runs on one and stops where the other's likelihood peaks; none:
    after ``iterations``."""
    bin: float | None = None
    """[m] Width of the fitted time bins, whole bins of the capture summed; default a
    quarter of the shortest wavelength of the field's band."""

    def __post_init__(self) -> None:
        require(self.iterations >= 1, "iterations", f"must be >= 1, got {self.iterations}")
        require(self.bin is None or self.bin > 0, "bin",
                f"must be > 0 m or null, got {self.bin}")


#: The options that had flat names before they were grouped: old name -> new name.
GROUPED = {
    "lobe": "lobe.exponent", "fit_lobe": "lobe.fit", "lobe_max": "lobe.max",
    "lobe_tolerance": "lobe.tolerance",
    "depth_range": "depth.range", "depth_step": "depth.step",
    "depth_threshold": "depth.threshold", "depth_iterations": "depth.iterations",
    "depth_margin": "depth.margin",
    "temporal_response": "response.temporal", "time_offset": "response.time_offset",
    "response_rounds": "response.rounds",
    "counts_iterations": "counts.iterations", "counts_stop": "counts.stop",
    "counts_bin": "counts.bin",
}


@dataclass(frozen=True)
class PriorOptions:
    """The options of the physics-constrained fit, without ``seed`` and ``device`` (the
    hybrids' group ``prior``; :class:`RSDPriorConfig` adds them)."""

    renamed_options: ClassVar[Mapping[str, str]] = GROUPED

    iterations: int = 150
    """FISTA iterations."""
    l1_weight: float = 0.02
    """L1 weight relative to max Re(A^H P) (at 1 the fitted albedo is zero)."""
    tv_weight: float = 0.0
    """Smoothed total-variation weight, relative like ``l1_weight`` (0: none)."""
    amplitude: Amplitude = Amplitude.lambertian
    """Amplitude of each leg: lambertian (surfaces facing the wall, the simulators'),
    point (point scatterers) or inverse_square (no cosines)."""
    lobe: LobeOptions = dataclasses.field(default_factory=LobeOptions)
    """A glossy lobe about the voxels' normal, fixed or fitted (lambertian amplitude only)."""
    fit_frequencies: int = 32
    """Frequencies used in the fit, evenly spread over the field's (0: all)."""
    depth: DepthOptions = dataclasses.field(default_factory=DepthOptions)
    """The voxel planes: given, or found by a quick coarse fit."""
    lateral_step: float | None = None
    """[m] Largest lateral voxel spacing; default half the shortest wavelength (a quarter
    for confocal scans). The training spacing is a whole multiple of the spacing used."""
    power_iterations: int = 20
    """Power iterations estimating the Lipschitz constant L."""
    step: float = 0.9
    """FISTA step as a fraction of 1/L (the power iteration estimates L from below)."""
    tolerance: float = 0.0
    """Stop when the objective falls by less than this fraction over 10 iterations (0: never)."""
    precision: Precision = Precision.single
    """FFT precision: complex64 (fast) or complex128."""
    workers: int = -1
    """Threads of scipy.fft (-1: all cores)."""
    cache_mb: float = 1024.0
    """[MiB] Memory for the kernels' spectra during the fit (recomputed when larger)."""
    background: Background = Background.none
    """Additive background fitted jointly: none, or constant (one complex offset per
    frequency, the same over the wall: ambient light, dark counts, a late tail)."""
    response: ResponseOptions = dataclasses.field(default_factory=ResponseOptions)
    """The system's temporal response and time-origin offset, fitted jointly."""
    likelihood: Likelihood = Likelihood.least_squares
    """The data term: least_squares; poisson (each wall point weighted by the inverse
    Poisson variance of its samples, from the capture's photon counts;
    :mod:`nlosfw.model.physics.likelihood`); or poisson_counts (the least-squares albedo
    refined by the exact Poisson likelihood of the counts in every time bin, with a
    background per bin; needs ``split.spectral=none``, and
    ``transform.remove_device_legs=false`` when the capture's times include the device
    legs; :mod:`nlosfw.model.physics.counts`)."""
    counts: CountsOptions = dataclasses.field(default_factory=CountsOptions)
    """``likelihood: poisson_counts``: the EM iterations, when they stop, the time bins."""

    @property
    def uses_noise_variance(self) -> bool:
        """With ``likelihood: poisson`` the fit needs the field's variance."""
        return self.likelihood == Likelihood.poisson

    @property
    def uses_photon_counts(self) -> bool:
        """With ``likelihood: poisson_counts`` the fit needs the field's photon counts."""
        return self.likelihood == Likelihood.poisson_counts

    def __post_init__(self) -> None:
        require(self.iterations >= 1, "iterations", f"must be >= 1, got {self.iterations}")
        require(0 <= self.l1_weight < 1, "l1_weight",
                f"must be in [0, 1) (1 zeroes the albedo), got {self.l1_weight}")
        require(self.tv_weight >= 0, "tv_weight", f"must be >= 0, got {self.tv_weight}")
        lobed = self.lobe.exponent != 0 or self.lobe.fit
        require(not lobed or self.amplitude == Amplitude.lambertian, "lobe",
                f"a lobe is about a surface's normal: needs amplitude lambertian, got "
                f"{self.amplitude}")
        require(self.fit_frequencies >= 0, "fit_frequencies",
                f"must be >= 0 (0: all), got {self.fit_frequencies}")
        require(self.lateral_step is None or self.lateral_step > 0, "lateral_step",
                f"must be > 0 m or null, got {self.lateral_step}")
        require(self.power_iterations >= 1, "power_iterations",
                f"must be >= 1, got {self.power_iterations}")
        require(0 < self.step <= 1, "step", f"must be in (0, 1], got {self.step}")
        require(0 <= self.tolerance < 1, "tolerance", f"must be in [0, 1), got {self.tolerance}")
        require_threads(self.workers, "workers", -1, "all cores")
        require(self.cache_mb >= 0, "cache_mb", f"must be >= 0 MiB, got {self.cache_mb}")


@dataclass(frozen=True)
class RSDPriorConfig(PriorOptions, FieldModelConfig):
    """Options of the ``rsd_prior`` field model (``seed``: the power iteration's start;
    ``device`` is ignored: numpy on the CPU)."""

    def __post_init__(self) -> None:
        FieldModelConfig.__post_init__(self)
        PriorOptions.__post_init__(self)

    def options(self) -> PriorOptions:
        """These options without ``seed`` and ``device``."""
        return PriorOptions(**{f.name: getattr(self, f.name)
                               for f in dataclasses.fields(PriorOptions)})


def prior_config(options: PriorOptions, seed: int, device: str = "auto") -> RSDPriorConfig:
    """``rsd_prior``'s config of ``options`` with ``seed`` and ``device`` (how a hybrid
    runs its group ``prior``)."""
    return RSDPriorConfig(seed=seed, device=device,
                          **{f.name: getattr(options, f.name)
                             for f in dataclasses.fields(PriorOptions)})


@contextmanager
def options_in_group(group: str) -> Iterator[None]:
    """Inside: a ConfigError about an option ``model.<name>`` of ``rsd_prior`` is raised as
    one about ``model.<group>.<name>``, the option's name in a hybrid that holds them as the
    group ``group``."""
    try:
        yield
    except ConfigError as err:
        if not err.option.startswith("model."):
            raise
        raise ConfigError(f"model.{group}.{err.option.removeprefix('model.')}",
                          err.problem) from None


def moved_into(group: str, names: Iterable[str]) -> dict[str, str]:
    """The ``renamed_options`` of a config that held the prior's options ``names`` flat and
    holds them in its group ``group`` now: old name -> ``group.<new name>``."""
    return {name: f"{group}.{GROUPED.get(name, name)}" for name in names}


#: The flat names of ``rsd_prior``'s options before they were grouped (``seed`` and
#: ``device`` aside).
FLAT_NAMES = (
    "iterations", "l1_weight", "tv_weight", "amplitude", "lobe", "fit_lobe", "lobe_max",
    "lobe_tolerance", "fit_frequencies", "depth_range", "depth_step", "lateral_step",
    "depth_threshold", "depth_iterations", "depth_margin", "power_iterations", "step",
    "tolerance", "precision", "workers", "cache_mb", "background", "temporal_response",
    "time_offset", "response_rounds", "likelihood", "counts_iterations", "counts_stop",
    "counts_bin")

"""The options of the ``rsd_prior`` field model (:mod:`nlosfw.model.physics.prior`)."""

from __future__ import annotations

from dataclasses import dataclass

from nlosfw.common.config import require
from nlosfw.image.fft import Precision
from nlosfw.model.interface import FieldModelConfig
from nlosfw.model.physics.background import Background
from nlosfw.model.physics.counts import CountsStop
from nlosfw.model.physics.likelihood import Likelihood
from nlosfw.model.physics.operator import Amplitude
from nlosfw.model.physics.response import TemporalResponse


@dataclass(frozen=True)
class RSDPriorConfig(FieldModelConfig):
    """Options of the ``rsd_prior`` field model (``seed``: the power iteration's start;
    ``device`` is ignored: numpy on the CPU)."""

    iterations: int = 150
    """FISTA iterations."""
    l1_weight: float = 0.02
    """L1 weight relative to max Re(A^H P) (at 1 the fitted albedo is zero)."""
    tv_weight: float = 0.0
    """Smoothed total-variation weight, relative like ``l1_weight`` (0: none)."""
    amplitude: Amplitude = Amplitude.lambertian
    """Amplitude of each leg: lambertian (surfaces facing the wall, the simulators'),
    point (point scatterers) or inverse_square (no cosines)."""
    lobe: float = 0.0
    """Exponent k of a glossy lobe about the voxels' normal, cos^k (lambertian amplitude
    only; 0: Lambertian)."""
    fit_lobe: bool = False
    """Fit k jointly with the albedo over [0, ``lobe_max``] instead
    (:mod:`nlosfw.model.physics.lobe`)."""
    lobe_max: float = 20.0
    """``fit_lobe``: the largest k searched."""
    lobe_tolerance: float = 0.25
    """``fit_lobe``: the search stops when k is known to within this."""
    fit_frequencies: int = 32
    """Frequencies used in the fit, evenly spread over the field's (0: all)."""
    depth_range: tuple[float, ...] = ()
    """[m] Near and far depth of the voxel planes; empty: estimated from the data."""
    depth_step: float | None = None
    """[m] Distance between voxel planes; default a fifth of the shortest wavelength."""
    lateral_step: float | None = None
    """[m] Largest lateral voxel spacing; default half the shortest wavelength (a quarter
    for confocal scans). The training spacing is a whole multiple of the spacing used."""
    depth_threshold: float = 0.1
    """Automatic depth range: keep the planes where the coarse fit's largest contribution
    reaches this fraction of the overall largest."""
    depth_iterations: int = 40
    """Automatic depth range: FISTA iterations of the coarse fit."""
    depth_margin: float = 0.05
    """Automatic depth range: metres added before and after the kept planes."""
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
    temporal_response: TemporalResponse = TemporalResponse.none
    """System temporal response fitted jointly: none, or gaussian (timing jitter, the gain
    exp(-(2 pi f sigma)^2 / 2)); :mod:`nlosfw.model.physics.response`."""
    time_offset: bool = False
    """Fit the capture's time-origin offset tau jointly (the phase ramp exp(-2 pi i f tau))."""
    response_rounds: int = 5
    """Rounds of the response search (with a response term on): each tries every fitted term
    either side of its value, the albedo fitted again each time (a quarter of
    ``iterations``), with steps halving; a round costs about one to two fits."""
    likelihood: Likelihood = Likelihood.least_squares
    """The data term: least_squares; poisson (each wall point weighted by the inverse
    Poisson variance of its samples, from the capture's photon counts;
    :mod:`nlosfw.model.physics.likelihood`); or poisson_counts (the least-squares albedo
    refined by the exact Poisson likelihood of the counts in every time bin, with a
    background per bin; needs ``split.spectral=none``, and
    ``transform.remove_device_legs=false`` when the capture's times include the device
    legs; :mod:`nlosfw.model.physics.counts`)."""
    counts_iterations: int = 100
    """``poisson_counts``: the most EM iterations on the counts."""
    counts_stop: CountsStop = CountsStop.likelihood
    """``poisson_counts``: when EM stops. likelihood: the counts are split binomially
    (``seed``) into two independent halves, EM runs on one and stops where the other's
    likelihood peaks; none: after ``counts_iterations``."""
    counts_bin: float | None = None
    """[m] ``poisson_counts``: width of the fitted time bins, whole bins of the capture
    summed; default a quarter of the shortest wavelength of the field's band."""

    @property
    def uses_noise_variance(self) -> bool:
        """With ``likelihood: poisson`` the fit needs the field's variance."""
        return self.likelihood == Likelihood.poisson

    @property
    def uses_photon_counts(self) -> bool:
        """With ``likelihood: poisson_counts`` the fit needs the field's photon counts."""
        return self.likelihood == Likelihood.poisson_counts

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.iterations >= 1, "iterations", f"must be >= 1, got {self.iterations}")
        require(0 <= self.l1_weight < 1, "l1_weight",
                f"must be in [0, 1) (1 zeroes the albedo), got {self.l1_weight}")
        require(self.tv_weight >= 0, "tv_weight", f"must be >= 0, got {self.tv_weight}")
        require(self.lobe >= 0, "lobe", f"must be >= 0 (0: Lambertian), got {self.lobe}")
        require((self.lobe == 0 and not self.fit_lobe) or self.amplitude == Amplitude.lambertian,
                "lobe", f"a lobe is about a surface's normal: needs amplitude lambertian, got "
                f"{self.amplitude}")
        require(not (self.fit_lobe and self.lobe), "lobe",
                "is fitted with fit_lobe: leave it 0, or set fit_lobe false to fix it")
        require(self.lobe_max > 0, "lobe_max", f"must be > 0, got {self.lobe_max}")
        require(self.lobe_tolerance > 0, "lobe_tolerance",
                f"must be > 0, got {self.lobe_tolerance}")
        require(self.fit_frequencies >= 0, "fit_frequencies",
                f"must be >= 0 (0: all), got {self.fit_frequencies}")
        require(len(self.depth_range) in (0, 2), "depth_range",
                f"must be empty (automatic) or [near, far], got {list(self.depth_range)}")
        if self.depth_range:
            near, far = self.depth_range
            require(0 < near <= far, "depth_range",
                    f"must satisfy 0 < near <= far (m), got {list(self.depth_range)}")
        for name in ("depth_step", "lateral_step"):
            value = getattr(self, name)
            require(value is None or value > 0, name, f"must be > 0 m or null, got {value}")
        require(0 < self.depth_threshold <= 1, "depth_threshold",
                f"must be in (0, 1], got {self.depth_threshold}")
        require(self.depth_iterations >= 1, "depth_iterations",
                f"must be >= 1, got {self.depth_iterations}")
        require(self.depth_margin >= 0, "depth_margin", f"must be >= 0 m, got {self.depth_margin}")
        require(self.power_iterations >= 1, "power_iterations",
                f"must be >= 1, got {self.power_iterations}")
        require(0 < self.step <= 1, "step", f"must be in (0, 1], got {self.step}")
        require(0 <= self.tolerance < 1, "tolerance", f"must be in [0, 1), got {self.tolerance}")
        require(self.workers == -1 or self.workers >= 1, "workers",
                f"must be -1 (all cores) or >= 1, got {self.workers}")
        require(self.cache_mb >= 0, "cache_mb", f"must be >= 0 MiB, got {self.cache_mb}")
        require(isinstance(self.time_offset, bool), "time_offset",
                f"must be true or false, got {self.time_offset!r}")
        require(self.response_rounds >= 1, "response_rounds",
                f"must be >= 1, got {self.response_rounds}")
        require(self.counts_iterations >= 1, "counts_iterations",
                f"must be >= 1, got {self.counts_iterations}")
        require(self.counts_bin is None or self.counts_bin > 0, "counts_bin",
                f"must be > 0 m or null, got {self.counts_bin}")

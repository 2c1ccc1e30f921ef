"""The options of the neural hidden volume (:mod:`nlosfw.model.hybrid.volume`): its
network's and its training's, and ``rsd_prior``'s that set up the lattice, as the group
``prior``."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

from nlosfw.common.config import require, require_threads
from nlosfw.model.interface import FieldModelConfig
from nlosfw.model.physics.background import Background
from nlosfw.model.physics.config import (
    PriorOptions,
    RSDPriorConfig,
    moved_into,
    prior_config,
)
from nlosfw.model.physics.likelihood import Likelihood
from nlosfw.model.physics.response import TemporalResponse

#: The network options the neural volume sets from its own: by the network's name, the
#: name of this model's option.
VOLUME_NAMES = {"seed": "seed", "device": "device", "hidden": "network_hidden",
                "steps": "steps", "lr": "lr", "threads": "threads",
                "validation_fraction": "validation_fraction"}
_VOLUME_SETS = frozenset(VOLUME_NAMES)


@dataclass(frozen=True)
class VolumePriorOptions(PriorOptions):
    """``rsd_prior``'s options as the neural volume uses them (its group ``prior``): they
    set up the lattice (``amplitude``, ``lobe``, ``depth``, ``lateral_step``,
    ``fit_frequencies``, ``precision``, ``workers``) and the coarse fits that find the depth
    planes and, with ``lobe.fit``, the lobe (``iterations``, ``l1_weight``, ...). The
    network trains by least squares on the whole wall field: a likelihood, a background
    or a response term is refused."""

    fit_frequencies: int = 0
    """Frequencies the network trains on, evenly spread over the field's (0, the default
    here: all; ``lobe.fit``'s search uses ``rsd_prior``'s default, 32)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, off in (("likelihood", Likelihood.least_squares),
                          ("background", Background.none),
                          ("response.temporal", TemporalResponse.none),
                          ("response.time_offset", False)):
            value = getattr(self.response, name.split(".")[1]) if "." in name else \
                getattr(self, name)
            require(value == off, name, f"the neural volume trains its network by least "
                    f"squares without this term; leave it {str(off).lower()} (use "
                    f"rsd_prior for it), got {value}")


@dataclass(frozen=True)
class NeuralVolumeConfig(FieldModelConfig):
    """Options of the neural hidden volume (``seed`` and ``device`` are the network's:
    ``auto`` trains it on a GPU when the backend sees one). The lattice options are
    ``rsd_prior``'s, in the group ``prior``."""

    #: The lattice options were this config's own, flat, before they became ``prior``.
    renamed_options: ClassVar[Mapping[str, str]] = moved_into("prior", (
        "amplitude", "lobe", "fit_lobe", "lobe_max", "fit_frequencies", "depth_range",
        "depth_step", "lateral_step", "depth_threshold", "depth_iterations", "depth_margin",
        "precision", "workers"))

    network: str = "siren"
    """The albedo's network: a name registered through ``register_networks`` for this
    model's backend (siren, fourier, hashgrid, ...)."""
    network_hidden: tuple[int, ...] = (64, 64)
    """Widths of the network's hidden layers."""
    network_options: dict[str, bool | int | float | str] = dataclasses.field(default_factory=dict)
    """Options of the network's own config (siren's ``omega0_first``, a hash grid's
    levels, ...), checked by it before the run; its widths, seed, device, steps, learning
    rate and threads are this model's options, refused here."""
    steps: int = 300
    """Adam steps (full batch: every kept sample at every training frequency); an upper
    bound when ``patience`` stops sooner."""
    validation_fraction: float = 0.1
    """Fraction of the kept wall points held out of the loss (chosen with ``seed``): the
    albedo of the step with the lowest error there is kept, so the network stops before it
    fits the noise of the points it trains on (0: none, the last step is kept). Needs 10 or
    more kept points."""
    patience: int = 50
    """Steps without a lower validation error before training stops (0: run every step;
    the best step's albedo is kept in every case)."""
    average_steps: int = 1
    """The kept albedo is the mean of the last ``average_steps`` steps' albedos up to the one
    with the lowest validation error (1: that step's alone), held while training as that
    many more albedos."""
    lr: float = 3e-3
    """Peak learning rate (cosine decay to ``lr * lr_final``)."""
    lr_final: float = 0.05
    """Final learning rate as a fraction of ``lr``."""
    albedo_start: float = 0.001
    """Albedo (times mean(n) / s, see the module docstring) where the network's output is
    0: the start is a faint, nearly uniform volume."""
    albedo_tv: float = 0.0
    """Weight of the albedo's total variation within each depth plane, relative to its sum
    (:func:`~nlosfw.model.hybrid.albedo_total_variation`), added to the loss over the
    number of wall points it sums: flat, sharp-edged targets then fit as plateaus, not as
    a smooth hill with one bright peak (0: none, the network's smoothness is the only
    prior). Per point, as a posterior's prior weighs against a sum of errors: 4 times
    fewer kept points, a term 4 times stronger against their relative error. The fit's
    loss and history include the term; the validation error that chooses the kept step is
    the data's alone."""
    albedo_tv_rise: float = 0.05
    """The most the term's weight (``albedo_tv`` over the points) rises a step, from 0 (0:
    at full weight from the first step). A weak term acts almost at once; a strong one (a
    sparse scan's) grows while the network finds the scene: from the faint, nearly uniform
    start a compact bright scene is the albedo of the highest relative total variation, and
    a strong term at once can hold the volume flat."""
    threads: int = 1
    """CPU threads of torch while training (0: torch's default; JAX ignores it)."""
    prior: VolumePriorOptions = dataclasses.field(default_factory=VolumePriorOptions)
    """``rsd_prior``'s options that set up the lattice: amplitude, lobe, depth planes,
    lateral step, frequencies, precision (``model.prior.depth.range``, ...)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        require(bool(self.network), "network", "must name a registered network, e.g. siren")
        taken = sorted(set(self.network_options) & _VOLUME_SETS)
        require(not taken, f"network_options.{taken[0] if taken else ''}",
                "is set by the neural volume's own options (network_hidden, seed, device, "
                "steps, lr, threads); set it there")
        require(len(self.network_hidden) >= 1 and all(h >= 1 for h in self.network_hidden),
                "network_hidden", f"must be one or more widths >= 1, got "
                f"{list(self.network_hidden)}")
        require(self.steps >= 1, "steps", f"must be >= 1, got {self.steps}")
        require(self.lr > 0 and math.isfinite(self.lr), "lr",
                f"must be > 0 and finite, got {self.lr}")
        require(0 < self.lr_final <= 1, "lr_final", f"must be in (0, 1], got {self.lr_final}")
        require(0 <= self.validation_fraction < 0.5, "validation_fraction",
                f"must be in [0, 0.5), got {self.validation_fraction}")
        require(self.patience >= 0, "patience", f"must be >= 0, got {self.patience}")
        require(self.average_steps >= 1, "average_steps",
                f"must be >= 1 (1: the best step's albedo alone), got {self.average_steps}")
        require(0 < self.albedo_start < 1, "albedo_start",
                f"must be in (0, 1), got {self.albedo_start}")
        require(self.albedo_tv >= 0 and math.isfinite(self.albedo_tv), "albedo_tv",
                f"must be >= 0 and finite, got {self.albedo_tv}")
        require(self.albedo_tv_rise >= 0 and math.isfinite(self.albedo_tv_rise),
                "albedo_tv_rise", f"must be >= 0 and finite, got {self.albedo_tv_rise}")
        require_threads(self.threads, "threads", 0, "torch's default")

    def prior_config(self) -> RSDPriorConfig:
        """``rsd_prior``'s config that finds the depth planes and predicts: the group
        ``prior`` with this config's ``seed``."""
        return prior_config(self.prior, self.seed)

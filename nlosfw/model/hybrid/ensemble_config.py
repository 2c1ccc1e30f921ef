"""The options of the stacked ensemble (:mod:`nlosfw.model.hybrid.ensemble`): its members
(``rsd_prior`` at several total-variation weights, the neural volume), the residual network
on their blend, and each one's options as a group."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from nlosfw.common.config import require
from nlosfw.common.cores import available_cores, worker_count
from nlosfw.model.hybrid.residual import RSDResidualConfig
from nlosfw.model.hybrid.volume_config import NeuralVolumeConfig, VolumePriorOptions
from nlosfw.model.interface import FieldModelConfig
from nlosfw.model.physics.config import PriorOptions, RSDPriorConfig, prior_config

#: The ensemble's ``volume.albedo_tv``: per kept wall point the loss sums (0.28 at 16x of a
#: 64 x 64 scan, 1.1 at 64x).
VOLUME_ALBEDO_TV = 64.0

#: The label of the neural volume member (the ``rsd_prior`` ones: :func:`prior_label`).
VOLUME_LABEL = "neural_volume"


def prior_label(tv_weight: float) -> str:
    """The label of the ``rsd_prior`` member fitted with ``tv_weight``: ``rsd_prior_tv0.03``."""
    return f"rsd_prior_tv{tv_weight:g}"


@dataclass(frozen=True)
class EnsembleConfig(FieldModelConfig):
    """Options of the stacked ensemble. ``seed`` and ``device`` are every member's (they
    replace the groups' own); ``volume.validation_fraction`` of the kept wall points (the
    points the neural volume holds out for its early stopping) weigh the members."""

    tv_weights: tuple[float, ...] = (0.03, 0.1, 0.3)
    """One ``rsd_prior`` member per weight: its ``tv_weight`` (a smoothed total variation
    of the albedo within each depth plane, relative like ``l1_weight``; 0: none), the other
    options ``prior``'s. Empty: no ``rsd_prior`` member. Above about 0.3 the 150 FISTA
    iterations no longer converge (the smoothed TV's gradient makes the step about 80 x
    tv_weight times smaller): the albedo is then a blurred, dim start."""
    neural_volume: bool = True
    """Whether the neural volume (``volume``'s options) is a member."""
    concurrent: bool = True
    """Fit the neural volume in a second thread while the ``rsd_prior`` members fit, on the
    cores the volume leaves (:attr:`workers_beside_volume`); false: one after another.
    Once the priors end, the volume trains on the cores they used too. Its sums then run
    on more threads, and the priors' on other threads than ``prior.workers``'s, than one
    after another: the results can differ in rounding."""
    add_residual: bool = True
    """Whether a residual network (``residual``'s options) is fitted to what the weighed
    members leave at the kept points, and added as far as the held-out points say it helps
    (a scale in [0, 1] of its penalised output)."""
    prior: PriorOptions = dataclasses.field(default_factory=PriorOptions)
    """``rsd_prior``'s options for its members (``model.prior.iterations``, ...), but for
    ``tv_weight`` (``tv_weights``)."""
    volume: NeuralVolumeConfig = dataclasses.field(default_factory=lambda: NeuralVolumeConfig(
        albedo_tv=VOLUME_ALBEDO_TV, prior=VolumePriorOptions(fit_frequencies=64)))
    """``neural_volume``'s options (``model.volume.steps``, ...), but for two defaults of the
    ensemble's own: ``albedo_tv`` (the albedo's total variation, 0 alone) and
    ``prior.fit_frequencies`` 64 (all alone). With the term the volume's image follows
    its field (its front view without the term: a smooth hill with one bright peak); 64 of
    the field's frequencies keep the ensemble's fit within its time (the measurements:
    ``studies/sparse_scans_measured/README.md``)."""
    residual: RSDResidualConfig = dataclasses.field(default_factory=RSDResidualConfig)
    """The residual network's options as ``rsd_residual``'s (``model.residual.network``,
    ``model.residual.residual_weight``, ...); its physics is the members' blend, so its
    group ``prior`` is not used and must stay at its defaults."""

    def __post_init__(self) -> None:
        super().__post_init__()
        weights = self.tv_weights
        require(all(math.isfinite(w) and w >= 0 for w in weights), "tv_weights",
                f"must be finite weights >= 0, got {list(weights)}")
        require(len(set(weights)) == len(weights), "tv_weights",
                f"each weight at most once, got {list(weights)}")
        require(self.member_count >= 1, "tv_weights",
                "must name a weight, or set neural_volume true: the ensemble needs a member")
        require(self.prior.tv_weight == 0, "prior.tv_weight",
                f"is set per member by tv_weights; leave it 0, got {self.prior.tv_weight}")
        require(self.residual.prior == PriorOptions(), "residual.prior",
                "is not used (the residual network's physics is the weighed members); leave "
                "it at its defaults")
        weighed = self.member_count > 1 or self.add_residual
        require(self.volume.validation_fraction > 0 or not weighed,
                "volume.validation_fraction",
                "must be > 0 to weigh members or a residual (the held-out kept points)")

    @property
    def member_count(self) -> int:
        """How many members are weighed."""
        return len(self.tv_weights) + int(self.neural_volume)

    @property
    def uses_noise_variance(self) -> bool:
        """With ``prior.likelihood: poisson`` the rsd_prior members need the variance."""
        return bool(self.tv_weights) and self.prior.uses_noise_variance

    @property
    def uses_photon_counts(self) -> bool:
        """With ``prior.likelihood: poisson_counts`` they need the photon counts."""
        return bool(self.tv_weights) and self.prior.uses_photon_counts

    def prior_member_config(self, tv_weight: float, workers: int | None = None
                            ) -> RSDPriorConfig:
        """``rsd_prior``'s config of the member fitted with ``tv_weight`` (on ``workers``
        threads, if given, else ``prior.workers``)."""
        options = dataclasses.replace(self.prior, tv_weight=tv_weight)
        if workers is not None:
            options = dataclasses.replace(options, workers=workers)
        return prior_config(options, self.seed, self.device)

    @property
    def workers_beside_volume(self) -> int:
        """The ``rsd_prior`` members' threads while the volume fits beside them: the cores
        the volume's threads leave, at most ``prior.workers``'s, at least 1."""
        volume = self.volume.threads if self.volume.threads > 0 else available_cores()
        return max(1, min(worker_count(self.prior.workers), available_cores() - volume))

    def residual_config(self) -> RSDResidualConfig:
        """The residual group with this config's seed and device."""
        return dataclasses.replace(self.residual, seed=self.seed, device=self.device)

    def volume_config(self) -> NeuralVolumeConfig:
        """The volume group with this config's seed and device."""
        return dataclasses.replace(self.volume, seed=self.seed, device=self.device)

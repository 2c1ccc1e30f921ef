"""Count splitting: one capture of photon counts as two independent ones.

Each bin's count n is split into a ~ Binomial(n, 1/2) and b = n - a (binomial thinning).
When n is Poisson with mean mu, a and b are independent Poisson counts with mean mu / 2
each: two captures (A and B) of the same scan at half the exposure, whose noises are
independent. A model trained on A and scored against B is not rewarded for copying A's
noise, and B's own noise is known (its variance is its mean, estimated by its counts),
which gives the error a perfect predictor would make: the noise floor
(:mod:`nlosfw.evaluation.noise_floor`).

Valid on raw integer counts and any step that keeps them integers (gate, crop, bin, stride,
integer shifts, transpose and flip), not after a background subtraction. Only
approximate where the counts are not Poisson: under dead time and pile-up (a SPAD in
histogram mode at high flux), and when the scan points were not each measured for the
same dwell time (the split halves every point's exposure, the sampling assumes equal
ones).

A simulated noisy capture stores its counts divided by ``scene_info.noise.counts_per_unit``
(:func:`~nlosfw.capture.photon_counts.count_scale`): its halves are divided back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.photon_counts import count_scale, photon_counts
from nlosfw.common.config import require_seed
from nlosfw.common.errors import ConfigError

#: The option that turns count splitting on (named in every refusal).
OPTION = "split.count_splitting"
#: The option that seeds the split.
SEED_OPTION = "split.count_splitting_seed"
#: What the refusals call the step.
PURPOSE = "count splitting"

#: Below this many photons the split is drawn before the run (:func:`check_count_split`).
DRAWN_BELOW = 64


@dataclass(frozen=True, eq=False)
class CountSplit:
    """The two halves of a capture of counts: ``a`` trains, ``b`` scores."""

    a: Capture
    b: Capture
    seed: int
    count_scale: float
    """Photon counts per unit of H (1 for a file of raw counts)."""
    counts_a: int
    counts_b: int

    @property
    def whole(self) -> Capture:
        """The histograms as measured: half A's and half B's counts added back together."""
        return self.a.replace(H=np.asarray(self.a.H) + np.asarray(self.b.H))


def capture_counts(capture: Capture, where: str) -> np.ndarray:
    """H as integer photon counts for count splitting
    (:func:`~nlosfw.capture.photon_counts.photon_counts`, refusals naming :data:`OPTION`)."""
    return photon_counts(capture, where, OPTION, PURPOSE)


def check_count_split(capture: Capture, seed: int, where: str) -> None:
    """A one-line error naming ``where`` unless count splitting with ``seed`` leaves both
    halves photons: a ConfigError for :data:`OPTION` when the capture holds fewer than
    two (or is not counts, :func:`capture_counts`), for :data:`SEED_OPTION` when every
    photon goes to one half. The halves are drawn only for fewer than
    :data:`DRAWN_BELOW` photons: with more, a half is empty with probability below 2^-63."""
    total = int(capture_counts(capture, where).sum())
    if total < 2:
        raise ConfigError(OPTION, f"{where}: holds {total} photon{'' if total == 1 else 's'} "
                                  "(after its preprocessing); count splitting needs at least 2, "
                                  "one for each half (training and scoring)")
    if total < DRAWN_BELOW:
        halves = split_counts(capture, seed, where)
        if 0 in (halves.counts_a, halves.counts_b):
            empty, use = ("A", "trains the models") if halves.counts_a == 0 else (
                "B", "scores them")
            raise ConfigError(SEED_OPTION, f"{where}: with seed {seed} all its "
                              f"{total} photons go to one half, leaving half {empty} (which "
                              f"{use}) none; choose another seed or a capture with more "
                              "photons")


def split_counts(capture: Capture, seed: int, where: str = "the capture") -> CountSplit:
    """Split every bin's count n into Binomial(n, 1/2) (capture A) and the rest (B), drawn
    with ``seed`` (0 to 2^63 - 1); both keep H's dtype and units (counts divided by the
    count scale)."""
    require_seed(seed, SEED_OPTION)
    counts = capture_counts(capture, where)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7417]))
    a = rng.binomial(counts, 0.5)
    b = counts - a
    scale = count_scale(capture)
    return CountSplit(a=_half(capture, a, scale, "A", seed),
                      b=_half(capture, b, scale, "B", seed), seed=int(seed),
                      count_scale=scale, counts_a=int(a.sum()), counts_b=int(b.sum()))


def _half(capture: Capture, counts: np.ndarray, scale: float, name: str, seed: int) -> Capture:
    dtype = capture.H.dtype
    H = (counts.astype(dtype) if np.issubdtype(dtype, np.integer)
         else (counts / scale).astype(dtype))
    info = dict(capture.scene_info)
    info["count_splitting"] = {"half": name, "seed": int(seed), "probability": 0.5}
    return capture.replace(H=H, scene_info=info)

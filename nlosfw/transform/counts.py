"""Photon counts of wall points summed into wider time bins, and their temporal DFT: what a
fit by the counts' own likelihood works on (``rsd_prior``'s ``poisson_counts``,
:mod:`nlosfw.model.physics.counts`). Sums of whole bins of Poisson counts are Poisson counts."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.transform.field import PhotonCounts
from nlosfw.transform.temporal_dft import unit_phasor


@dataclass(frozen=True, eq=False)
class BinnedCounts:
    """Counts of N wall points in J bins of ``factor`` capture bins each."""

    counts: np.ndarray
    """(J, N) photons per bin and point."""
    edges: np.ndarray
    """(J + 1,) bin edges in metres of path."""
    points: np.ndarray
    """(N, 3) the wall points."""
    factor: int
    """Capture bins summed into one bin."""
    source: PhotonCounts
    """The counts they were summed from (time axis and count scale)."""

    def field_of(self, per_bin: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """The phasor field (the capture's units, as the transform makes it) of ``per_bin``
        photons (J,) spread evenly over each bin's capture bins: (F,) complex."""
        k, step = self.factor, self.source.delta_t
        photons = np.repeat(np.asarray(per_bin, dtype=float) / k, k)
        centres = self.edges[0] + (np.arange(photons.size) + 0.5) * step
        kernel = unit_phasor(-np.outer(np.asarray(frequencies, dtype=float), centres))
        return np.asarray(kernel @ photons * step / self.source.count_scale, np.complex128)


def bin_counts(counts: PhotonCounts, wall_xyz: np.ndarray, bin_width: float) -> BinnedCounts:
    """The counts (of the points ``wall_xyz``, in the counts' wall layout) summed into bins
    of the largest whole number of capture bins not wider than ``bin_width`` (m), from the
    first bin holding a count (a gate's zeros are not measurements) to the last whole bin."""
    n_raw = counts.counts.reshape(counts.counts.shape[0], -1)
    points = np.asarray(wall_xyz, dtype=float).reshape(-1, 3)
    if n_raw.shape[1] != points.shape[0]:
        raise DataError(f"counts: {n_raw.shape[1]} wall points for {points.shape[0]} points")
    factor = max(1, int(math.floor(bin_width / counts.delta_t + 1e-9)))
    hits = np.flatnonzero(n_raw.sum(axis=1) > 0)
    if hits.size == 0:
        raise DataError("counts: the wall points caught no photon")
    first = int(hits[0])
    n_bins = (n_raw.shape[0] - first) // factor
    if n_bins < 1:
        raise DataError(f"counts: fewer capture bins after the first count than one bin of "
                        f"{bin_width:.4g} m holds; use narrower bins")
    binned = n_raw[first:first + n_bins * factor].reshape(n_bins, factor, -1).sum(axis=1)
    width = factor * counts.delta_t
    edges = counts.t_start + first * counts.delta_t + width * np.arange(n_bins + 1)
    return BinnedCounts(binned, edges, points, factor, counts)


def check_counts_times(geometry: CaptureGeometry, transform_config: object, where: str
                       ) -> None:
    """A one-line ConfigError for ``transform.remove_device_legs`` naming the capture
    ``where`` when the transform would take the device legs out of the field while the
    counts keep them in their times: a fit of both needs the same times."""
    if (geometry.t_accounts_first_and_last_bounces
            and getattr(transform_config, "remove_device_legs", False)):
        raise ConfigError("transform.remove_device_legs", f"{where}: the photon counts' "
                          "likelihood models the counts in the capture's own times, which "
                          "include the device legs; set transform.remove_device_legs=false")

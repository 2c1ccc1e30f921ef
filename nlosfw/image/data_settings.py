"""The transient imagers' settings estimated from the data they image.

``lct``, ``fk`` and ``fbp`` undo a radiometric falloff, and ``lct`` regularises its inverse
with a Wiener SNR. When neither the imager's option nor the capture (its ``imaging_hints``,
:mod:`nlosfw.capture.hints`) sets one, the imager estimates it from the field, never from a
file's name, path or content hash:

* **Wiener SNR** (``lct``): the field's per-frequency signal shares measured from its
  evanescent region (:func:`nlosfw.image.evanescent.evanescent_noise_weights`, the same
  measure ``fbp``'s Wiener weights use): with s the mean share over the band,
  ``snr = s / (1 - s)``, the signal's share of the band over the noise's, kept within
  :data:`SNR_RANGE` (a noise-free field: the top of it). A field with no evanescent region
  to measure gets :data:`DEFAULT_SNR`, O'Toole's default.
* **falloff**: the candidate (:data:`FALLOFFS`) whose volume is the sharpest by the focus
  measure :func:`sparsity` (the volume's intensity normalised fourth moment), each candidate
  imaged by the imager itself at the planes asked for, on the wall binned 2 x 2 as often
  as each side keeps at least :data:`MIN_BINNED_SIDE` samples (:func:`binned_wall`: a
  64 x 64 scan is judged on 16 x 16) to keep the estimate cheap; a tie keeps the first
  candidate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.image.evanescent import evanescent_noise_weights

#: The Wiener SNR without an option, a hint or an evanescent region (O'Toole's code: 8e-2).
DEFAULT_SNR = 0.08
#: [low, high] of an estimated Wiener SNR.
SNR_RANGE = (0.01, 10.0)
#: The falloffs the estimate chooses from, in the order a tie keeps.
FALLOFFS = ("diffuse", "retroreflective")
#: Fewest wall samples along an axis that the falloff's estimate bins the wall down to.
MIN_BINNED_SIDE = 16


@dataclass(frozen=True)
class Estimate:
    """An estimated setting and the one line that says how it was found."""

    value: float
    why: str


def estimated_snr(values: np.ndarray, frequencies: np.ndarray,
                  spacing: tuple[float, float]) -> Estimate:
    """The Wiener SNR of a confocal field on a regular wall grid (module docstring);
    ``values`` (F, Y, X), ``frequencies`` in cycles per metre of path, ``spacing`` (dy, dx)."""
    noise = evanescent_noise_weights(values, frequencies, spacing)
    if noise.measured == 0:
        return Estimate(DEFAULT_SNR, f"snr {DEFAULT_SNR:g}: the default (no evanescent "
                                     "region to measure the noise in)")
    share = float(np.mean(noise.weights))
    low, high = SNR_RANGE
    snr = high if share >= 1 else float(np.clip(share / (1 - share), low, high))
    return Estimate(snr, f"snr {snr:.3g} estimated from the data: the band's signal share "
                         f"{share:.3f} (evanescent noise, {noise.measured} frequencies)")


def sparsity(intensity: np.ndarray) -> float:
    """The focus measure: N sum(I^2) / (sum I)^2 of the N voxels' intensities, 1 for a
    uniform volume, N for a single bright voxel (0 for an empty one)."""
    i = np.asarray(intensity, dtype=np.float64).ravel()
    total = float(i.sum())
    return 0.0 if total <= 0 else float(i.size * (i @ i) / (total * total))


def binned_wall(values: np.ndarray, origin: tuple[float, float],
                spacing: tuple[float, float]
                ) -> tuple[np.ndarray, tuple[float, float], tuple[float, float]]:
    """(values, origin, spacing) of a wall grid (F, Y, X) with each 2 x 2 block of samples
    summed (a trailing odd row or column dropped), again while both sides keep at least
    :data:`MIN_BINNED_SIDE` samples; the grid as it is when a side has fewer than twice
    that."""
    while min(values.shape[1:]) >= 2 * MIN_BINNED_SIDE:
        n_f, ny, nx = values.shape
        my, mx = ny // 2, nx // 2
        values = values[:, :2 * my, :2 * mx].reshape(n_f, my, 2, mx, 2).sum(axis=(2, 4))
        origin = (origin[0] + spacing[0] / 2, origin[1] + spacing[1] / 2)
        spacing = (2 * spacing[0], 2 * spacing[1])
    return values, origin, spacing

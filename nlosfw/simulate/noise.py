"""Measurement noise for simulated captures: timing jitter, photon (Poisson) noise, dark counts."""

from __future__ import annotations

import numpy as np

from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.capture.pileup import piled_up_counts
from nlosfw.simulate.scene import NoiseConfig


def apply_noise(H: np.ndarray, delta_t: float, noise: NoiseConfig,
                rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """A noisy copy of ``H`` (time on axis 0) in the same units, and a record of what was done.

    Jitter blurs every time profile with a Gaussian of standard deviation
    ``jitter_ps`` (converted to metres of path). Poisson noise scales ``H`` so
    that the capture holds ``photons`` expected signal photons, adds
    ``dark_counts`` expected counts per sensor spread evenly over the bins,
    draws counts, and scales back, so the noisy capture's expectation is ``H``
    plus the dark-count floor. With ``pulses`` the detector records at most the first
    photon of each of that many pulses per scan point (pile-up,
    :mod:`nlosfw.capture.pileup`): the counts are drawn from the first-photon
    distribution, and the expectation is no longer ``H``.
    """
    out = np.array(H, dtype=np.float64, copy=True)
    info: dict = {"model": noise.model, "jitter_ps": float(noise.jitter_ps)}
    if noise.jitter_ps > 0:
        sigma_bins = noise.jitter_ps * 1e-12 * SPEED_OF_LIGHT / delta_t
        from scipy.ndimage import gaussian_filter1d  # only when there is jitter to apply

        out = gaussian_filter1d(out, sigma_bins, axis=0, mode="constant")
        info["jitter_sigma_bins"] = float(sigma_bins)
    if noise.model == "poisson":
        total = float(out.sum())
        if total <= 0:
            scale = 1.0
        else:
            scale = noise.photons / total
        dark_per_bin = noise.dark_counts / out.shape[0]
        mean = out * scale + dark_per_bin
        if noise.pulses is None:
            counts = rng.poisson(mean)
        else:
            counts = piled_up_counts(mean, noise.pulses, rng)
            info["pulses"] = int(noise.pulses)
        out = counts / scale
        info.update(photons=float(noise.photons), dark_counts=float(noise.dark_counts),
                    counts_per_unit=float(scale), total_counts=int(counts.sum()))
    return out.astype(np.float32), info

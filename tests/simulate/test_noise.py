"""Measurement noise: Poisson photon counts, dark counts, timing jitter."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.common.errors import ConfigError
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.noise import apply_noise
from nlosfw.simulate.scene import NoiseConfig, scene_from_config
from nlosfw.testing.fixtures import tiny_scene_config


def profile(bins: int = 200) -> np.ndarray:
    t = np.arange(bins)
    H = np.exp(-0.5 * ((t - 80) / 6.0) ** 2)
    return np.stack([H, 0.5 * H], axis=1)[:, :, None]          # (T, 2, 1)


def test_no_noise_is_an_exact_float32_copy():
    H = profile()
    out, info = apply_noise(H, 0.003, NoiseConfig(), np.random.default_rng(0))
    assert out.dtype == np.float32 and info["model"] == "none"
    np.testing.assert_array_equal(out, H.astype(np.float32))


def test_poisson_noise_is_unbiased_with_the_right_variance():
    H = profile()
    noise = NoiseConfig(model="poisson", photons=5000.0, dark_counts=20.0)
    draws = np.stack([apply_noise(H, 0.003, noise, np.random.default_rng(s))[0]
                      for s in range(400)]).astype(float)
    scale = noise.photons / H.sum()
    floor = noise.dark_counts / H.shape[0] / scale              # dark counts in H's units
    mean = draws.mean(axis=0)
    assert mean.sum() == pytest.approx(H.sum() + floor * H[0].size * H.shape[0], rel=0.01)
    peak = (slice(70, 90), 0, 0)
    np.testing.assert_allclose(mean[peak], H[peak] + floor, rtol=0.05)
    expected_var = (H[peak] + floor) / scale                    # Poisson: var = mean counts
    np.testing.assert_allclose(draws[(slice(None),) + peak].var(axis=0), expected_var,
                               rtol=0.25)
    _, info = apply_noise(H, 0.003, noise, np.random.default_rng(0))
    assert info["total_counts"] == pytest.approx(noise.photons + 2 * noise.dark_counts,
                                                 rel=0.05)


def test_jitter_blurs_with_the_given_picoseconds():
    H = np.zeros((400, 1, 1))
    H[200] = 1.0
    dt = 0.003
    out, info = apply_noise(H, dt, NoiseConfig(jitter_ps=50.0), np.random.default_rng(0))
    sigma_bins = 50e-12 * SPEED_OF_LIGHT / dt                   # 50 ps = 1.5 cm = 5 bins
    assert info["jitter_sigma_bins"] == pytest.approx(sigma_bins)
    t = np.arange(400) - 200
    w = out[:, 0, 0].astype(float)
    assert w.sum() == pytest.approx(1.0, rel=1e-5)
    assert np.sqrt((w * t**2).sum() / w.sum()) == pytest.approx(sigma_bins, rel=0.02)


def test_simulate_adds_seeded_noise_and_records_it():
    config = tiny_scene_config()
    config["noise"] = {"model": "poisson", "photons": 1e4, "jitter_ps": 20.0}
    scene = scene_from_config(config)
    a = AnalyticSimulator({"seed": 3}).simulate(scene)
    b = AnalyticSimulator({"seed": 3}).simulate(scene)
    c = AnalyticSimulator({"seed": 4}).simulate(scene)
    np.testing.assert_array_equal(a.H, b.H)
    assert not np.array_equal(a.H, c.H)
    assert a.scene_info["noise"]["model"] == "poisson"
    assert a.scene_info["noise"]["photons"] == 1e4


def test_bad_noise_options_are_refused():
    for options, name in (({"photons": 0}, "photons"), ({"dark_counts": -1}, "dark_counts"),
                          ({"jitter_ps": -2}, "jitter_ps"), ({"model": "gauss"}, "model")):
        config = tiny_scene_config()
        config["noise"] = options
        with pytest.raises(ConfigError, match=rf"noise\.{name}"):
            scene_from_config(config)

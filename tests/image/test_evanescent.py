"""fbp's Wiener weights from the field's evanescent region (nlosfw.image.evanescent) and the
transient imagers' end taper, against fields whose signal and noise are known."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.image.evanescent import evanescent_noise_weights
from nlosfw.image.transient import END_TAPER, end_taper

SPACING = 0.01                                   # 1 cm: lateral Nyquist 50 cycles/m
FREQUENCIES = np.arange(1.0, 41.0, 1.0)          # 2 f beyond Nyquist from 25 cycles/m on


def point_field(depth: float = 0.6, n: int = 32) -> np.ndarray:
    """The confocal field (F, Y, X) of one hidden point: exp(2 pi i f 2 r) / r^2."""
    axis = (np.arange(n) - (n - 1) / 2) * SPACING
    r = np.sqrt(axis[:, None] ** 2 + axis[None, :] ** 2 + depth**2)
    return np.exp(2j * np.pi * FREQUENCIES[:, None, None] * 2 * r) / r**2


def white_noise(shape: tuple[int, ...], sigma: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return sigma * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)


def test_a_noise_free_field_keeps_its_frequencies():
    weights = evanescent_noise_weights(point_field(), FREQUENCIES, (SPACING, SPACING))
    # N is measured where the square of lateral frequencies (side 1/SPACING) keeps a quarter
    # outside the circle of radius 2 f: pi (2 f)^2 <= 3/4 (1/SPACING)^2, f <= 24.4 here
    limit = np.sqrt(0.75 / np.pi) / SPACING / 2
    assert weights.measured == int(np.count_nonzero(limit >= FREQUENCIES)) == 24
    assert weights.weights.min() > 0.97


def test_pure_noise_is_weighted_to_about_zero():
    noise = white_noise((FREQUENCIES.size, 32, 32), 1.0, seed=1)
    weights = evanescent_noise_weights(noise, FREQUENCIES, (SPACING, SPACING))
    assert weights.noise_power == pytest.approx(1.0, rel=0.1)   # E|n|^2 = sigma^2
    assert weights.weights.max() < 0.2


@pytest.mark.parametrize("seed", [2, 3])
def test_signal_and_white_noise_give_the_wiener_weight(seed):
    """W(f) = S / (S + N) with S the signal's mean power (Parseval) and N = sigma^2, also
    where 2 f is past the wall's Nyquist frequency (N taken as white there)."""
    signal = point_field()
    power = np.mean(np.abs(signal) ** 2, axis=(1, 2))              # same at every f here
    sigma2 = float(power.mean())                                   # SNR 1: W = 1/2
    noisy = signal + white_noise(signal.shape, np.sqrt(sigma2), seed)
    weights = evanescent_noise_weights(noisy, FREQUENCIES, (SPACING, SPACING)).weights
    expected = power / (power + sigma2)
    np.testing.assert_allclose(weights, expected, atol=0.08)


def test_no_evanescent_region_leaves_the_field_alone():
    high = np.array([30.0, 31.0])                                  # 2 f > Nyquist everywhere
    weights = evanescent_noise_weights(point_field()[:2], high, (SPACING, SPACING))
    assert weights.measured == 0 and np.all(weights.weights == 1.0)


def test_the_end_taper_is_one_then_a_raised_cosine_to_zero():
    window = (0.5, 2.5)
    edge = END_TAPER * 2.0
    t = np.array([0.5, 2.5 - edge - 1e-9, 2.5 - edge / 2, 2.5 - 1e-12])
    np.testing.assert_allclose(end_taper(t, window), [1.0, 1.0, 0.5, 0.0], atol=1e-6)
    assert np.all(end_taper(t, (0.0, np.inf)) == 1.0)


def test_a_zero_filled_sub_grid_is_weighted_from_its_own_samples():
    """The sparse raw source (every second row and column, zeros between) gets the weights
    of its samples, not of the spectral copies the zeros put in the evanescent region."""
    full = point_field(n=32)
    sub_weights = evanescent_noise_weights(full[:, ::2, ::2], FREQUENCIES,
                                           (2 * SPACING, 2 * SPACING)).weights
    filled = np.zeros_like(full)
    filled[:, ::2, ::2] = full[:, ::2, ::2]
    weights = evanescent_noise_weights(filled, FREQUENCIES, (SPACING, SPACING)).weights
    np.testing.assert_allclose(weights, sub_weights, rtol=1e-12)
    irregular = filled.copy()
    irregular[:, 4, :] = 0                     # rows 0, 2, 6, 8, ...: no regular sub-grid
    result = evanescent_noise_weights(irregular, FREQUENCIES, (SPACING, SPACING))
    assert result.measured == 0 and np.all(result.weights == 1.0)

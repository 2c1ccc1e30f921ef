"""The transient imagers' falloff and Wiener SNR estimated from the data
(nlosfw.image.data_settings): what the estimate measures, and that an option still wins."""

from __future__ import annotations

import re

import numpy as np
import pytest

from nlosfw.image.data_settings import (
    DEFAULT_SNR,
    FALLOFFS,
    SNR_RANGE,
    binned_wall,
    estimated_snr,
    sparsity,
)
from nlosfw.image.evanescent import evanescent_noise_weights
from nlosfw.image.fk import FKImager
from nlosfw.image.lct import FBPImager, LCTImager, LCTImagerConfig
from nlosfw.image.transient import Falloff, TransientImagerConfig, canonical_wall
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.fft import FFTTransform

SPACING = (0.02, 0.02)


def test_the_snr_is_the_signal_share_of_the_band_over_the_noise_share():
    rng = np.random.default_rng(0)
    freqs = np.linspace(1.0, 20.0, 12)
    # a smooth (signal) part plus white noise: the estimate is s / (1 - s) of the mean
    # share s the evanescent measure reports
    y, x = np.mgrid[:32, :32] * SPACING[0]
    smooth = np.exp(-((x - 0.3) ** 2 + (y - 0.3) ** 2) / 0.02)
    noise = rng.normal(size=(12, 32, 32)) + 1j * rng.normal(size=(12, 32, 32))
    signal = smooth[None] * np.exp(2j * np.pi * freqs[:, None, None] * 0.1)
    values = signal + 0.2 * noise
    share = float(np.mean(evanescent_noise_weights(values, freqs, SPACING).weights))
    estimate = estimated_snr(values, freqs, SPACING)
    assert 0.2 < share < 0.8
    assert estimate.value == pytest.approx(share / (1 - share), rel=1e-12)
    assert "estimated from the data" in estimate.why
    # more noise, a lower snr
    assert estimated_snr(signal + 0.5 * noise, freqs, SPACING).value < 0.3 * estimate.value


def test_the_snr_of_noise_alone_a_noise_free_field_and_an_unmeasurable_one():
    rng = np.random.default_rng(1)
    freqs = np.linspace(1.0, 20.0, 12)
    noise = rng.normal(size=(12, 32, 32)) + 1j * rng.normal(size=(12, 32, 32))
    assert estimated_snr(noise, freqs, SPACING).value == pytest.approx(SNR_RANGE[0], rel=0.5)
    flat = np.ones((12, 32, 32), complex)          # all power at k = 0: no noise at all
    assert estimated_snr(flat, freqs, SPACING).value == SNR_RANGE[1]
    # no evanescent region (2 f beyond the wall's Nyquist at every frequency): the default
    high = np.linspace(100.0, 200.0, 4)
    unmeasured = estimated_snr(noise[:4], high, SPACING)
    assert unmeasured.value == DEFAULT_SNR and "default" in unmeasured.why


def test_sparsity_and_the_binned_wall():
    assert sparsity(np.ones((4, 5))) == pytest.approx(1.0)
    one = np.zeros((4, 5))
    one[1, 2] = 3.0
    assert sparsity(one) == pytest.approx(20.0)
    assert sparsity(np.zeros(3)) == 0.0
    values = np.arange(2 * 65 * 64, dtype=float).reshape(2, 65, 64)
    binned, origin, spacing = binned_wall(values, (0.0, 1.0), (0.1, 0.2))
    # 65 x 64 -> 32 x 32 -> 16 x 16: each side keeps at least 16 samples
    assert binned.shape == (2, 16, 16) and binned[1, 0, 0] == values[1, :4, :4].sum()
    assert origin == pytest.approx((0.15, 1.3)) and spacing == pytest.approx((0.4, 0.8))
    small = np.ones((1, 31, 40))
    assert binned_wall(small, (0.0, 0.0), (0.1, 0.1))[0] is small


@pytest.fixture(scope="module")
def noisy_field():
    """A confocal letter in the LCT layout with Poisson noise: a field with both signal
    and an evanescent noise floor."""
    config = layouts.lct_scene(resolution=16, bins=1700)
    config["noise"] = {"model": "poisson", "photons": 1e3}
    capture = AnalyticSimulator().simulate(scene_from_config(config))
    field = FFTTransform().transform(capture)
    return field, fixtures.aligned_voxels(field.wall_xyz, np.linspace(0.45, 0.75, 16))


@pytest.mark.parametrize("imager", [LCTImager, FKImager, FBPImager])
def test_imagers_estimate_the_falloff_by_focus_unless_it_is_set(noisy_field, imager):
    field, voxels = noisy_field
    estimated = imager().reconstruct(field, voxels)
    settings = estimated.metadata["settings"]
    assert estimated.metadata["falloff"] in FALLOFFS
    assert f"falloff {estimated.metadata['falloff']} estimated from the data" in settings
    # the estimate is the candidate whose volume is the sharper on the binned wall
    scores = {c: float(v) for v, c in re.findall(r"([0-9.e+-]+) (diffuse|retroreflective)",
                                                  settings.split("sparsity")[1])}
    assert estimated.metadata["falloff"] == max(FALLOFFS, key=lambda c: scores[c])
    # the option wins, and is said
    other = next(c for c in FALLOFFS if c != estimated.metadata["falloff"])
    config = {"falloff": Falloff(other)}
    chosen = imager(imager.config_class(**config)).reconstruct(field, voxels)
    assert chosen.metadata["falloff"] == other
    assert f"falloff {other}: the falloff option" in chosen.metadata["settings"]
    # an image with the estimate is an image with that falloff set explicitly
    fixed = imager(imager.config_class(falloff=Falloff(estimated.metadata["falloff"]))
                   ).reconstruct(field, voxels)
    np.testing.assert_array_equal(fixed.intensity, estimated.intensity)


def test_lct_estimates_its_snr_from_the_field_unless_it_is_set(noisy_field):
    field, voxels = noisy_field
    grid = canonical_wall(field)
    expected = estimated_snr(grid.values, field.frequencies, grid.spacing).value
    estimated = LCTImager().reconstruct(field, voxels)
    assert estimated.metadata["snr"] == pytest.approx(expected, rel=1e-12)
    assert SNR_RANGE[0] < expected < SNR_RANGE[1]
    given = LCTImager(LCTImagerConfig(snr=0.5)).reconstruct(field, voxels)
    assert given.metadata["snr"] == 0.5 and "snr 0.5: the snr option" in \
        given.metadata["settings"]
    # settings settled once (as a run does for all its sources), then imaged: said once
    imager = LCTImager(LCTImagerConfig(snr=0.5))
    hints = imager.settled_hints(field, voxels)
    again = imager.reconstruct(field.replace(imaging_hints=hints), voxels)
    assert again.metadata["settings"] == hints.origin
    assert again.metadata["settings"].count("the snr option") == 1
    np.testing.assert_array_equal(again.intensity, given.intensity)
    assert not np.array_equal(given.intensity, estimated.intensity)
    # fk and fbp take no snr and estimate none
    assert FKImager(TransientImagerConfig()).reconstruct(field, voxels).metadata.get(
        "snr") is None

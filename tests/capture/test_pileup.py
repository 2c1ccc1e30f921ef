"""Pile-up of a single-photon detector and Coates' correction (``capture.pileup_pulses``):
the first-photon distribution against a pulse-by-pulse simulation, the estimator against
known rates, the preprocessing step, the simulated detector and a whole capture stage."""

from __future__ import annotations

import numpy as np
import pytest

import nlosfw
from nlosfw.capture.pileup import (
    coates_rates,
    correct_pileup,
    first_photon_probabilities,
    piled_up_counts,
)
from nlosfw.capture.preprocess import Extras, Preprocessing, preprocess
from nlosfw.common.errors import ConfigError
from nlosfw.pipeline.settings import run_settings
from nlosfw.testing.fixtures import tiny_capture

#: Mean photons per pulse in each of 40 bins: a bright early peak (the direct reflection,
#: 1.2 photons per pulse in bin 5) and a weak late signal (0.01 per pulse in bins 25-29).
RATES = np.full(40, 2e-4)
RATES[5] = 1.2
RATES[25:30] = 0.01


def test_first_photon_probabilities_match_a_pulse_by_pulse_simulation():
    """Every pulse drawn photon by photon (Poisson in every bin), its first photon kept: the
    histogram of 200,000 pulses agrees with N p_i within 4 standard errors in every bin,
    and the pulses with no photon with exp(-sum lambda)."""
    pulses = 200_000
    rng = np.random.default_rng(5)
    photons = rng.poisson(RATES, size=(pulses, RATES.size))
    hit = photons.any(axis=1)
    first = np.argmax(photons > 0, axis=1)[hit]
    histogram = np.bincount(first, minlength=RATES.size)
    p = first_photon_probabilities(RATES)
    sigma = np.sqrt(pulses * p * (1 - p))
    assert np.all(np.abs(histogram - pulses * p) < 4 * sigma + 1)
    assert (~hit).mean() == pytest.approx(np.exp(-RATES.sum()), abs=4e-3)
    assert 1 - p.sum() == pytest.approx(np.exp(-RATES.sum()), rel=1e-12)


def test_coates_inverts_the_expected_counts_exactly():
    pulses = 10_000
    expected = pulses * first_photon_probabilities(RATES[:, None] * np.ones((1, 3)))
    assert np.allclose(coates_rates(expected, pulses), RATES[:, None], rtol=1e-10, atol=0)


def test_coates_recovers_the_late_signal_the_raw_counts_hide():
    """Behind 1.2 photons per pulse in bin 5, raw counts show the late signal at
    exp(-1.2) = 30% of its rate; Coates' estimate from drawn counts (256 histograms of
    20,000 pulses) recovers it to 2% on average."""
    pulses = 20_000
    rng = np.random.default_rng(11)
    expected = np.broadcast_to(RATES[:, None] * pulses, (RATES.size, 256))
    counts = piled_up_counts(expected, pulses, rng)
    late = slice(25, 30)
    raw = counts[late].mean() / (pulses * RATES[late].mean())
    assert raw == pytest.approx(np.exp(-1.2) * np.exp(-RATES[6:25].sum()), rel=0.03)
    assert raw < 0.35
    corrected = coates_rates(counts, pulses)
    assert corrected[late].mean() / RATES[late].mean() == pytest.approx(1.0, abs=0.02)
    assert corrected[5].mean() == pytest.approx(1.2, rel=0.02)


def test_the_step_corrects_counts_in_the_captures_units():
    """A simulated capture stores counts / counts_per_unit: the estimate is N lambda in the
    same units, recorded with the pulses and the worst point's detection fraction."""
    base = tiny_capture(resolution=4, bins=40, bin_width=0.04)
    counts = piled_up_counts(np.broadcast_to(RATES[:, None, None] * 500, (40, 4, 4)), 500,
                             np.random.default_rng(0))
    scale = 250.0
    info = {**base.scene_info, "noise": {"model": "poisson", "counts_per_unit": scale}}
    capture = base.replace(H=(counts / scale).astype(np.float32), scene_info=info)
    before = capture.H.copy()
    out, steps = preprocess(capture, Preprocessing(pileup_pulses=500))
    assert np.allclose(out.H, coates_rates(counts, 500) * 500 / scale, rtol=1e-5)
    assert out.H.dtype == capture.H.dtype and np.array_equal(capture.H, before)
    assert out.scene_info["pileup"]["pulses"] == 500
    worst = counts.sum(axis=0).max() / 500
    assert out.scene_info["pileup"]["largest_detection_probability"] == pytest.approx(worst)
    assert [s.option for s in steps] == ["pileup_pulses"] and "Coates" in steps[0].effect


def test_the_background_capture_is_corrected_like_the_capture():
    base = tiny_capture(resolution=4, bins=40, bin_width=0.04)
    rng = np.random.default_rng(1)
    shape = (40, 4, 4)
    signal = base.replace(H=piled_up_counts(np.broadcast_to(RATES[:, None, None] * 800, shape),
                                            800, rng).astype(np.float32))
    dark = np.full(40, 0.05)
    background = base.replace(H=piled_up_counts(np.broadcast_to(dark[:, None, None] * 800,
                                                                shape), 800, rng)
                              .astype(np.float32))
    out, steps = preprocess(signal, Preprocessing(pileup_pulses=800, background="bg"),
                            extras=Extras(background=background))
    expected = (correct_pileup(signal, 800).H - correct_pileup(background, 800).H)
    assert np.allclose(out.H, expected)
    assert "corrected for pile-up" in steps[1].effect


@pytest.mark.parametrize("pulses, H, why", [
    (100, np.full((40, 4, 4), 3.0, dtype=np.float32), "holds 120 counts, at least the 100 "
                                                      "pulses given.*more than 120"),
    (1000, np.full((40, 4, 4), 0.37, dtype=np.float32), "not integer photon counts.*pile-up "
                                                        "correction needs raw counts"),
    (1000, np.full((40, 4, 4), -1.0, dtype=np.float32), "negative values"),
])
def test_what_cannot_be_corrected_is_refused_in_one_line(pulses, H, why):
    capture = tiny_capture(resolution=4, bins=40, bin_width=0.04).replace(H=H)
    with pytest.raises(ConfigError, match=why) as err:
        correct_pileup(capture, pulses, where="scan.mat")
    assert err.value.option == "capture.pileup_pulses" and "scan.mat" in str(err.value)
    assert "\n" not in str(err.value)


def test_a_file_with_too_few_pulses_is_refused_naming_it(tmp_path, monkeypatch, capsys):
    from nlosfw.capture.hdf5 import write_capture
    from nlosfw.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "counts.hdf5"
    write_capture(path, tiny_capture(resolution=4, bins=40, bin_width=0.04).replace(
        H=np.full((40, 4, 4), 3.0, dtype=np.float32)))
    status = main([f"capture.path={path}", "capture.pileup_pulses=100", "model=interp"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert err.startswith("error: capture.pileup_pulses: ") and str(path) in err
    assert "more than 120" in err and not (tmp_path / "outputs").exists()


def test_simulated_pileup_needs_photon_counts():
    from nlosfw.simulate.scene import NoiseConfig

    with pytest.raises(ConfigError, match="set model poisson") as err:
        NoiseConfig(model="none", pulses=1000)
    assert err.value.option == "pulses"
    with pytest.raises(ConfigError, match="must be >= 1"):
        NoiseConfig(model="poisson", pulses=0)


def test_the_options_refuse_no_pulses_and_count_splitting():
    with pytest.raises(ConfigError, match="must be >= 1") as err:
        Preprocessing(pileup_pulses=0)
    assert err.value.option == "pileup_pulses"
    with pytest.raises(ConfigError, match="capture.pileup_pulses") as err:
        run_settings({"split": {"count_splitting": True},
                      "capture": {"pileup_pulses": 1000}})
    assert err.value.option == "split.count_splitting"


def test_a_simulated_detector_with_pileup_is_corrected_in_the_capture_stage(tmp_path,
                                                                            monkeypatch):
    """The tiny scene with 5e5 photons over 2000 pulses per point (up to 84% of a point's
    pulses detect a photon): the raw counts are 61% of the ideal ones, 43% off and their
    centroids 1.2 bins early; corrected, the total is within 1%, the error that of the
    photon noise (9.4%) and the centroids within 0.05 bins. The noise-free capture (the
    scores' reference) is not corrected."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    base = ["scene=tiny", "scene.noise.model=poisson", "scene.noise.photons=5e5",
            "scene.noise.pulses=2000", "stop_after=capture", "model=interp"]
    results = {}
    for name, extra in (("raw", []), ("corrected", ["capture.pileup_pulses=2000"])):
        stage = nlosfw.run([*base, *extra], output_dir=tmp_path / name).stages.capture
        assert stage is not None and stage.clean is not None
        H = np.asarray(stage.capture.H, dtype=np.float64)
        clean = np.asarray(stage.clean.H, dtype=np.float64)
        bins = np.arange(H.shape[0])[:, None, None]
        lit = clean.sum(axis=0) > 0
        shift = ((H * bins).sum(axis=0)[lit] / H.sum(axis=0)[lit]
                 - (clean * bins).sum(axis=0)[lit] / clean.sum(axis=0)[lit])
        results[name] = (np.linalg.norm(H - clean) / np.linalg.norm(clean), H.sum() / clean.sum(),
                         shift.mean(), stage.capture.scene_info)
    raw, corrected = results["raw"], results["corrected"]
    assert raw[0] > 0.3 and raw[1] < 0.7 and raw[2] < -0.8
    assert corrected[0] < 0.12 and corrected[1] == pytest.approx(1.0, abs=0.01)
    assert abs(corrected[2]) < 0.05
    assert corrected[3]["pileup"]["pulses"] == 2000 and corrected[3]["noise"]["pulses"] == 2000
    assert "pileup" not in raw[3]

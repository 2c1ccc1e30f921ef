"""``rsd_prior``'s terms for real systems recover known values from embree captures: timing
jitter (the simulator's ``jitter_ps``), a time-origin offset (the histogram shifted by whole
bins) and a background (a late tail added at every wall point), alone and together."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nlosfw import run
from nlosfw.capture import SPEED_OF_LIGHT
from nlosfw.evaluation import split_field
from nlosfw.plugins import load_plugins
from nlosfw.simulate import scene_from_config
from nlosfw.testing import heldout_error_db, tiny_scene_config
from nlosfw.transform import FFTTransform

pytest.importorskip("embreex")

from nlosfw_embree.simulator import EmbreeSimulator

BIN = 0.006                                      # m of path per bin: 20.01 ps
BIN_PS = BIN / SPEED_OF_LIGHT * 1e12
JITTER_PS = 80.0
SHIFT_BINS = 4
#: One voxel plane at the patch's depth, voxels a quarter of the kept points' spacing apart
#: (on coarser voxels the albedo's blur in depth and across voxels absorbs part of the terms).
OPTIONS = {"depth": {"range": [0.5, 0.5]}, "lateral_step": 1 / 32, "l1_weight": 1e-3,
           "iterations": 300, "workers": 1}
TERMS = {"response": {"temporal": "gaussian", "time_offset": True}, "background": "constant"}


@pytest.fixture(scope="module")
def captures():
    """(transform, the capture with every term, the tail alone as a capture): an 8 cm
    Lambertian patch 0.5 m from a 1 m wall of 16 x 16 points, rendered by embree with 80 ps
    of jitter, shifted 4 bins late, plus a tail exp(-(t - 1.3 m) / 0.2 m) of 0.3 times the
    histograms' peak at every point."""
    config = tiny_scene_config(resolution=16, bins=300, bin_width=BIN, target=(0.03, -0.02, 0.5),
                               patch=0.08)
    config["noise"] = {"jitter_ps": JITTER_PS}
    capture = EmbreeSimulator({"samples": 1 << 12}).simulate(scene_from_config(config))
    shifted = np.zeros_like(capture.H)
    shifted[SHIFT_BINS:] = capture.H[:-SHIFT_BINS]
    t = np.arange(capture.H.shape[0]) * BIN
    tail = 0.3 * float(capture.H.max()) * np.where(t > 1.3, np.exp(-(t - 1.3) / 0.2), 0.0)
    tail_histograms = np.broadcast_to(tail[:, None, None], capture.H.shape).astype(np.float32)
    transform = FFTTransform({"n_frequencies": 10, "f_min": 2.0, "f_max": 4.0})
    return transform, capture.replace(H=shifted + tail_histograms), capture.replace(
        H=tail_histograms.copy())


def _fit(field, options):
    """The model fitted on every other point (every frequency), and its held-out error (dB)
    at the other points."""
    split = split_field(field, spatial_step=2, spectral="none")
    model = load_plugins().registry.create("model", "rsd_prior", {**OPTIONS, **options})
    report = model.fit(split.train_field)
    predicted = model.predict(field.wall_xyz[..., :2], field.frequencies)
    return model, report.fitted, heldout_error_db(predicted, field.values,
                                                  ~split.spatial_mask)


def test_jitter_offset_and_background_are_recovered_together(captures):
    """All three fitted jointly: sigma to 10% (measured 76.4 ps of 80), tau to half a bin
    (76.8 ps of 80.1; the histogram's bins hold a path from their start, 10 ps early on
    average), the offsets to 5% of their largest (0.9%); the held-out error falls from
    -7.4 dB without the terms to -41.4 dB."""
    transform, capture, tail = captures
    field = transform.transform(capture)
    model, fitted, with_terms = _fit(field, TERMS)
    _, _, without = _fit(field, {})
    assert fitted["response_sigma_ps"] == pytest.approx(JITTER_PS, rel=0.1)
    assert fitted["time_offset_ps"] == pytest.approx(SHIFT_BINS * BIN_PS, abs=0.5 * BIN_PS)
    offsets = transform.transform(tail).values.mean(axis=(1, 2))
    recovered = model.background.at(field.frequencies)
    assert np.abs(recovered - offsets).max() < 0.05 * np.abs(offsets).max()
    assert with_terms < without - 25.0, (with_terms, without)


@pytest.mark.parametrize("term", ["temporal", "time_offset"])
def test_each_response_term_alone_finds_its_value(captures, term):
    """The jitter alone (no shift, no tail): sigma to 5% (measured 78.9 ps); the shift alone:
    tau to half a bin (77.1 ps)."""
    transform, _, _ = captures
    config = tiny_scene_config(resolution=16, bins=300, bin_width=BIN, target=(0.03, -0.02, 0.5),
                               patch=0.08)
    if term == "temporal":
        config["noise"] = {"jitter_ps": JITTER_PS}
    capture = EmbreeSimulator({"samples": 1 << 12}).simulate(scene_from_config(config))
    if term == "time_offset":
        shifted = np.zeros_like(capture.H)
        shifted[SHIFT_BINS:] = capture.H[:-SHIFT_BINS]
        capture = capture.replace(H=shifted)
    option = {"temporal": "gaussian"} if term == "temporal" else {"time_offset": True}
    _, fitted, _ = _fit(transform.transform(capture), {"response": option})
    if term == "temporal":
        assert fitted.keys() == {"response_sigma_ps"}
        assert fitted["response_sigma_ps"] == pytest.approx(JITTER_PS, rel=0.05)
    else:
        assert fitted.keys() == {"time_offset_ps"}
        assert fitted["time_offset_ps"] == pytest.approx(SHIFT_BINS * BIN_PS, abs=0.5 * BIN_PS)


def test_the_counts_likelihood_recovers_the_dark_counts_with_the_jitter(tmp_path, monkeypatch):
    """``likelihood: poisson_counts`` on an embree capture of photon counts with 80 ps of
    jitter and 0.5 dark counts a bin: the jitter is fitted first (by least squares) and the
    counts' EM, with that pulse, finds the dark counts again. Measured: 83.2 ps and 0.495."""
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    out = run(["simulator=embree", "scene=tiny", "scene.noise.model=poisson",
               "scene.noise.photons=1e6", "scene.noise.dark_counts=256",
               f"scene.noise.jitter_ps={JITTER_PS}", "model=rsd_prior",
               "model.likelihood=poisson_counts", "model.response.temporal=gaussian",
               "model.counts.stop=likelihood", "split.spectral=none",
               "transform.n_frequencies=21", "reconstruction.n_depths=4",
               "figures.enabled=false"], output_dir=tmp_path / "run")
    fitted = json.loads((out.dir / "metrics.json").read_text())["field"]["model"]["fit"][
        "fitted"]
    assert fitted["response_sigma_ps"] == pytest.approx(JITTER_PS, rel=0.1)
    assert fitted["counts_background"] == pytest.approx(0.5, rel=0.05)
    assert fitted["counts_iterations"] >= 1 and fitted["counts_loglik_gain"] > 0

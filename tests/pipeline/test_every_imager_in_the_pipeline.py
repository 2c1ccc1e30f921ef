"""Every installed imager through the whole pipeline: a tiny simulated confocal
capture with the default split (the ``raw`` source is the 8 x 8 sub-grid of a 16 x 16 scan),
each source imaged, the patch found where it is."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import nlosfw
from nlosfw.plugins import load_plugins

PATCH_DEPTH = 0.6
IMAGERS = sorted(load_plugins().registry.names("imager"))


@pytest.mark.parametrize("imager", IMAGERS)
def test_imager_runs_in_the_pipeline_from_a_confocal_capture(tmp_path, monkeypatch, caplog,
                                                             imager):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    with caplog.at_level(logging.WARNING):
        out = nlosfw.run(["scene=tiny", "scene.capture.type=confocal", "model=interp",
                          f"imager={imager}", "figures.enabled=false",
                          "reconstruction.depth_range=[0.4,0.8]", "reconstruction.n_depths=9",
                          "reconstruction.single_frequency_images=0"],
                         output_dir=tmp_path / "run")
    recons = out.results.reconstructions
    assert set(recons.by_source) >= {"true", "raw", "interp"}
    depths = np.linspace(0.4, 0.8, 9)
    for source, recon in recons.by_source.items():
        profile = recon.intensity.reshape(depths.size, -1).max(axis=1)
        assert np.all(np.isfinite(recon.intensity)) and profile.max() > 0, (imager, source)
        # the patch is 0.6 m deep: the brightest plane within one plane (5 cm) of it
        assert abs(depths[int(np.argmax(profile))] - PATCH_DEPTH) <= 0.051, (imager, source)
    if imager in ("lct", "fk", "fbp"):    # time-domain imagers: no band-aliasing warning
        assert not [r for r in caplog.records if "alias" in r.getMessage()]


def test_a_measured_capture_is_imaged_over_the_measured_band_by_time_domain_imagers(
        tmp_path, monkeypatch, caplog):
    from nlosfw.image.transient import MEASURED_BAND
    from nlosfw.simulate.analytic import AnalyticSimulator
    from nlosfw.simulate.scene import scene_from_config
    from nlosfw.testing import layouts

    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    config = layouts.lct_scene(resolution=8, bins=1600)
    capture = AnalyticSimulator().simulate(scene_from_config(config))
    path = layouts.write_lct(tmp_path / "scan.mat", capture)
    bands = {}
    for imager in ("lct", "fft"):
        with caplog.at_level(logging.WARNING):
            out = nlosfw.run([f"capture.path={path}", f"imager={imager}", "model=interp",
                              "stop_after=transform", "capture.gate.bins=0"],
                             output_dir=tmp_path / imager)
        bands[imager] = out.metrics.transform.frequency_band
    lo, hi = bands["lct"]
    df = 1 / (capture.n_bins * capture.delta_t)        # the capture's DFT bins
    assert MEASURED_BAND[0] <= lo < MEASURED_BAND[0] + df
    assert MEASURED_BAND[1] - df < hi <= MEASURED_BAND[1]
    assert bands["fft"][1] < 20 < hi                   # fft keeps the wall-aliasing band

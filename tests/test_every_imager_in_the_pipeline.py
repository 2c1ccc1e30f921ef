"""Every installed imager through the whole pipeline (issue 21): a tiny simulated confocal
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

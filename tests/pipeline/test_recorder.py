"""The stages compute a run's scores and hand them on in their results; the metrics
recorder writes them into metrics.json as they are."""

from __future__ import annotations

import nlosfw

QUICK = ["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=11", "reconstruction.n_depths=4",
         "scene.noise.model=poisson", "split.count_splitting=true"]


def test_metrics_json_holds_the_sections_the_stages_computed(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    out = nlosfw.run(QUICK, output_dir=tmp_path / "run")
    stages, metrics = out.stages, out.metrics
    assert stages.capture is not None and stages.transform is not None
    assert stages.fit is not None and stages.fields is not None
    assert stages.reconstructions is not None
    assert metrics.capture == stages.capture.metrics
    assert metrics.capture is not None and metrics.capture.count_splitting is not None
    assert metrics.transform == stages.transform.metrics
    assert metrics.split == stages.fit.split_metrics
    scores = stages.fields.scores["interp"]
    entry = metrics.field_entry("interp")
    assert entry is not None and entry.splits == scores.splits
    assert entry.splits is not None and entry.splits.heldout_measurement is not None
    assert entry.denoising == scores.denoising is not None
    assert entry.fit == stages.fit.field_metrics["interp"].fit
    assert metrics.reconstruction == stages.reconstructions.metrics
    assert metrics.reconstruction is not None and "ceiling" in metrics.reconstruction.sources

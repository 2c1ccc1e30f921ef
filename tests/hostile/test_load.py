"""Load: a sweep of short jobs on the joblib launcher (2 workers) sharing one cache; the
small version of ``benchmarks/pipeline/bench_sweep.py`` (200 jobs)."""

from __future__ import annotations

import json

import pytest
import yaml

from nlosfw.pipeline.cache import cache_entries, file_digest

#: Three seeds x two models: the two jobs of a seed run at once on the two workers and want
#: the same capture and field (three such races per sweep; the benchmark runs 200 jobs).
JOBS = 6
SWEEP = ("-m", "hydra/launcher=parallel", "scene=tiny", "scene.noise.model=poisson",
         "scene.noise.photons=1e5", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=21", "reconstruction.n_depths=4",
         f"simulator.seed=range(0,{JOBS // 2})", "model=interp,nearest")


@pytest.mark.slow
def test_a_parallel_sweep_sharing_one_cache(workdir, tools):
    """Every job completes and writes its metrics; each capture and field, wanted by two
    jobs at once, is computed once and stored whole; nothing temporary is left."""
    sweep = workdir / "sweep"
    result = tools.nlosfw(*SWEEP, f"hydra.sweep.dir={sweep}", cwd=workdir)
    assert result.returncode == 0, result.stderr
    runs = [json.loads((sweep / str(n) / "metrics.json").read_text()) for n in range(JOBS)]
    assert [r["status"] for r in runs] == ["completed"] * JOBS
    configs = [yaml.safe_load((sweep / str(n) / "config.yaml").read_text()) for n in range(JOBS)]
    assert {(c["model"]["name"], c["simulator"]["seed"]) for c in configs} == {
        (m, s) for m in ("interp", "nearest") for s in range(JOBS // 2)}
    entries = cache_entries(workdir / "cache")
    kinds = sorted(e.path.parent.name for e in entries)
    # per seed: the clean and the noisy capture, and their two fields
    assert kinds == ["captures"] * JOBS + ["fields"] * JOBS
    for entry in entries:
        assert entry.check.read_text().strip() == file_digest(entry.path)
    hits = sum(bool(r["capture"]["cache_hit"]) for r in runs)
    assert hits == JOBS // 2   # the second job of each seed found the first one's capture
    assert not tools.temporaries(sweep) and not tools.temporaries(workdir / "cache")

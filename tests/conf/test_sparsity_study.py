"""The sparsity study in small: the preset's sweep on the tiny scene, its report
and the benchmark script that collects it."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import nlosfw
from nlosfw.cli import main

ROOT = Path(__file__).resolve().parents[2]
STUDY = ROOT / "studies" / "sparse_scans_simulated" / "run.py"
#: The study at its smallest: the tiny scene (16 x 16 wall), two sparsities, one neural model
#: with two seeds and few steps, few frequencies and depth planes.
TINY_STUDY = ["experiment=sparsity", "scene=tiny", "acquisition=clean", "split.spatial_step=2,4",
              "model=siren_torch", "model.seed=0,1", "model.steps=30",
              "transform.n_frequencies=21", "reconstruction.n_depths=8"]


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "200", "NLOSFW_CACHE_DIR": str(cwd / "cache")}
    result = subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=600, check=False)
    assert result.returncode == 0, f"{result.stdout}\n{result.stderr}"
    return result


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("study")
    sweep = tmp / "sweep"
    _run("-m", "nlosfw", "-m", *TINY_STUDY, f"hydra.sweep.dir={sweep}", cwd=tmp)
    # the report in-process (its command line is tests/cli/test_cli.py's and the presets')
    assert main(["report", str(sweep)]) == 0
    return sweep


def _metrics(sweep: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(sweep.glob("*/metrics.json"))]


def test_every_run_scores_every_source_against_the_full_capture(tiny_study):
    runs = _metrics(tiny_study)
    assert len(runs) == 4 and {r["status"] for r in runs} == {"completed"}
    for m in runs:
        sources = m["reconstruction"]["sources"]
        assert list(sources) == ["true", "raw", "model", "interp"]
        true = sources["true"]
        assert true["psnr"] is None and true["volume_psnr"] is None     # inf: stored as null
        assert true["ssim"] == pytest.approx(1.0) and true["volume_ssim"] == pytest.approx(1.0)
        assert true["rmse"] == 0.0
        # the tiny scene's patch at 0.6 m against 8 planes from the ground truth's span
        assert 0 < true["depth_rmse_m"] < 0.05
        for source in ("raw", "model", "interp"):
            assert math.isfinite(sources[source]["psnr"]) and sources[source]["ssim"] < 1
    by_step = {}
    for m in runs:
        by_step.setdefault(m["split"]["spatial_step"], []).append(m)
    assert {s: len(v) for s, v in by_step.items()} == {2: 2, 4: 2}
    assert [m["split"]["undersampling"] for m in by_step[4]] == [16.0, 16.0]
    assert by_step[4][0]["split"]["train_samples"] == 16
    # raw and interp do not depend on the model's seed; the model does
    for runs_at in by_step.values():
        a, b = (m["reconstruction"]["sources"] for m in runs_at)
        assert a["raw"] == {**b["raw"], "seconds": a["raw"]["seconds"]}
        assert a["interp"]["psnr"] == b["interp"]["psnr"]
        assert a["model"]["psnr"] != b["model"]["psnr"]
        assert sorted(m["field"]["model"]["seed"] for m in runs_at) == [0, 1]
    # 16x fewer samples of the tiny scene lose well over 10 dB against 4x (44.8 -> 18.7 dB)
    raw_psnr = {s: v[0]["reconstruction"]["sources"]["raw"]["psnr"] for s, v in by_step.items()}
    assert raw_psnr[2] > 40 and raw_psnr[4] < raw_psnr[2] - 15


def test_the_report_aggregates_seeds(tiny_study):
    report = tiny_study / "report"
    with (report / "report.csv").open() as fh:
        per_run = list(csv.DictReader(fh))
    assert len(per_run) == 4
    for column in ("seed", "undersampling", "raw_psnr", "raw_ssim", "interp_volume_psnr",
                   "model_volume_ssim", "model_depth_rmse_m", "true_depth_rmse_m"):
        assert all(row[column] != "" for row in per_run), column
    with (report / "study.csv").open() as fh:
        study = list(csv.DictReader(fh))
    assert [(r["undersampling"], r["series"]) for r in study] == [
        (u, s) for u in ("4", "16") for s in ("true", "raw", "interp", "siren_torch [steps=30]")]
    for row in study:
        assert row["runs"] == "2"
        assert row["seeds"] == ("0 1" if row["kind"] == "model" else "")
        if row["kind"] != "model":          # identical in both runs: no spread
            assert float(row["ssim_std"]) == 0.0
    model = next(r for r in study if r["kind"] == "model" and r["undersampling"] == "4")
    seeds = [m["reconstruction"]["sources"]["model"]["psnr"] for m in _metrics(tiny_study)
             if m["split"]["spatial_step"] == 2]
    assert float(model["psnr_mean"]) == pytest.approx(np.mean(seeds), rel=1e-5)
    assert float(model["psnr_std"]) == pytest.approx(np.std(seeds, ddof=1), rel=1e-4)
    assert float(model["psnr_min"]) == pytest.approx(min(seeds), rel=1e-5)
    text = (report / "report.md").read_text()
    assert "## Reconstruction quality against sparsity" in text
    # report.md escapes Markdown's link brackets in untrusted text
    assert "| tiny, analytic" in text and r"siren_torch \[steps=30\]" in text
    assert (report / "report.png").stat().st_size > 10_000


def test_the_study_script_collects_the_study(tiny_study, tmp_path):
    out = tmp_path / "study.json"
    result = _run(str(STUDY), "collect", str(tiny_study), "--out", str(out), cwd=tmp_path)
    data = json.loads(out.read_text())
    assert data["runs"] == data["completed"] == 4
    assert data["overrides"]["split.spatial_step"] == ["2", "4"]
    assert data["overrides"]["model.seed"] == ["0", "1"]
    assert len(data["rows"]) == 8 and data["fit_seconds"]["siren_torch"]["runs"] == 4
    assert "| tiny, analytic" in result.stdout and "PSNR gain (dB)" in result.stdout


def printed_config(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    """What ``nlosfw ARGS --cfg ...`` prints, read as YAML (the command run in-process)."""
    capsys.readouterr()
    assert main(args) == 0
    return yaml.safe_load(capsys.readouterr().out)


def test_the_preset_declares_the_study_and_the_acquisitions_pair_simulator_and_noise(
        tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    job = printed_config(["experiment=sparsity", "acquisition=noisy", "--cfg", "job"], capsys)
    assert job["simulator"]["name"] == "embree" and job["scene"]["noise"]["model"] == "poisson"
    assert job["model"]["name"] == "siren_torch" and job["figures"]["enabled"] is False
    job = printed_config(["experiment=sparsity", "acquisition=clean", "scene.noise.photons=10",
                          "--cfg", "job"], capsys)
    assert job["simulator"]["name"] == "analytic" and job["scene"]["noise"]["model"] == "none"
    hydra = printed_config(["experiment=sparsity", "--cfg", "hydra"], capsys)["hydra"]
    assert hydra["sweeper"]["params"] == {
        "scene": "thesis_planes,thesis_concave,letter_t,thesis_two_planes,thesis_occluded",
        "acquisition": "clean,noisy", "split.spatial_step": "2,4,8",
        "model": "siren_torch,fourier_torch,rsd_prior", "model.seed": "0,1,2"}


def test_the_study_on_a_capture_file_drops_the_scene_axes(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    made = nlosfw.run(["scene=tiny", "stop_after=capture"], output_dir=tmp_path / "made")
    capture = made.dir / "capture.hdf5"
    sweep, out = tmp_path / "sweep", tmp_path / "study.json"
    _run(str(STUDY), "run", "--dir", str(sweep),
         "--capture", str(capture), "--out", str(out), "split.spatial_step=2", "model=siren_torch",
         "model.seed=0,1", "model.steps=10", "transform.n_frequencies=21",
         "reconstruction.n_depths=8", cwd=tmp_path)
    runs = _metrics(sweep)
    assert len(runs) == 2                                  # one per seed: no scene axis
    assert {m["capture"]["source"] for m in runs} == {"file"}
    conditions = {row["condition"] for row in json.loads(out.read_text())["rows"]}
    assert conditions == {"capture.hdf5 reconstruction.n_depths=8 transform.n_frequencies=21"}


def test_the_study_figure_legend_wraps_to_the_figure_width():
    """Short labels take one row of up to six columns; labels carrying a model's options
    (about 80 characters) take fewer columns, each row narrower than the figure."""
    from nlosfw.report.study import legend_columns

    short = ["interp", "raw", "rsd_prior", "ceiling", "siren_torch"]
    assert legend_columns(short, 11.0) == 5
    long = ["neural_volume_torch [fit_frequencies=16 network_hidden=[32,32] steps=100] "
            "(mean, min-max over seeds)", "rsd_prior (mean, min-max over seeds)",
            "rsd_residual_torch (mean, min-max over seeds)", "interp", "raw", "ceiling"]
    columns = legend_columns(long, 11.0)
    assert 1 <= columns < 6
    widest_row = sum(sorted((0.6 + 0.075 * len(label) for label in long), reverse=True)
                     [:columns])
    assert widest_row <= 0.95 * 11.0
    assert legend_columns([long[0]], 4.0) == 1


def test_a_random_pattern_is_drawn_apart_from_the_grid_in_the_same_colour():
    """The study figure tells a model's random-pattern line from its grid line by a dashed
    line and hollow markers, in the model's one colour; the references keep their own line
    style and only go hollow."""
    from nlosfw.report.study import series_style

    colours: dict = {}
    grid = series_style("rsd_prior", "grid", "model", colours)
    scattered = series_style("rsd_prior", "random", "model", colours)
    other = series_style("siren_torch", "random", "model", colours)
    assert grid.color == scattered.color != other.color
    assert (grid.linestyle, grid.fillstyle) == ("-", "full")
    assert (scattered.linestyle, scattered.fillstyle) == ("--", "none")
    interp_grid = series_style("interp", "grid", "reference", colours)
    interp_random = series_style("interp", "random", "reference", colours)
    assert interp_grid.linestyle == interp_random.linestyle == ":"
    assert (interp_grid.fillstyle, interp_random.fillstyle) == ("full", "none")

"""Count splitting: the binomial split of photon counts, its refusals, the noise floor of the
held-out measurement error, and a run with it end to end.

The statistics are checked against Poisson theory (a Poisson(mu) count split binomially with p = 1/2
gives two independent Poisson(mu / 2) counts) and the floor against a Monte-Carlo estimate
over independently drawn captures."""

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

from nlosfw.capture.data import Capture
from nlosfw.capture.hdf5 import write_capture
from nlosfw.capture.photon_counts import count_scale, count_variance
from nlosfw.cli import main
from nlosfw.common.errors import ConfigError
from nlosfw.evaluation.count_splitting import capture_counts, split_counts
from nlosfw.evaluation.heldout import HeldoutMeasurement, heldout_measurement
from nlosfw.evaluation.noise_floor import field_variance, kernel_power
from nlosfw.pipeline.settings import run_settings
from nlosfw.testing.fixtures import tiny_capture
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import PhasorField
from nlosfw.transform.interface import PhasorTransform
from nlosfw.transform.wavelet import WaveletTransform

ROOT = Path(__file__).resolve().parents[2]
#: The measured captures: ../shared/data/real beside the project ($NLOSFW_REAL_DATA overrides).
REAL = Path(os.environ.get("NLOSFW_REAL_DATA") or ROOT.parent / "shared" / "data" / "real")


def _counts_capture(mean_scale: float, seed: int = 0, resolution: int = 8) -> tuple[Capture,
                                                                                     np.ndarray]:
    """The tiny scene's transient scaled to ``mean_scale`` expected counts in its brightest
    bin (plus a flat floor of 0.2 counts per bin) and one Poisson draw of it: (capture of
    counts, expected counts)."""
    clean = tiny_capture(resolution=resolution, bins=128, bin_width=0.02)
    mu = np.asarray(clean.H, dtype=np.float64)
    mu = mu / mu.max() * mean_scale + 0.2
    counts = np.random.default_rng(seed).poisson(mu).astype(np.float32)
    return clean.replace(H=counts), mu


# ---------------------------------------------------------------- the split's statistics
def test_halves_add_up_and_are_independent_poisson_halves():
    mu = 7.0
    base = tiny_capture(resolution=4, bins=400)
    big = np.random.default_rng(2).poisson(mu, size=(20000, 4, 4)).astype(np.float32)
    capture = base.replace(H=big)
    halves = split_counts(capture, seed=3)
    a = np.asarray(halves.a.H, dtype=np.float64)
    b = np.asarray(halves.b.H, dtype=np.float64)
    assert np.array_equal(a + b, big)                       # n = a + b, bin by bin
    assert halves.counts_a + halves.counts_b == int(big.sum())
    # Poisson(mu / 2) each: mean = variance = 3.5 (320,000 bins: standard error ~0.0033)
    assert a.mean() == pytest.approx(3.5, abs=0.02) and b.mean() == pytest.approx(3.5, abs=0.02)
    assert a.var() == pytest.approx(3.5, rel=0.02) and b.var() == pytest.approx(3.5, rel=0.02)
    # independent: correlation 0 (a fixed-n binomial split would give -1; the standard
    # error of r is 1/sqrt(320000) ~ 0.0018)
    r = np.corrcoef(a.ravel(), b.ravel())[0, 1]
    assert abs(r) < 0.01
    # the same seed splits the same way, another seed differently
    again = split_counts(capture, seed=3)
    assert np.array_equal(again.a.H, halves.a.H)
    assert not np.array_equal(split_counts(capture, seed=4).a.H, halves.a.H)


def test_a_fixed_count_splits_binomially():
    """Given n, A's count is Binomial(n, 1/2): mean n/2, variance n/4."""
    base = tiny_capture(resolution=4, bins=400)
    H = np.full((400, 4, 4), 10.0, dtype=np.float32)
    a = np.concatenate([np.asarray(split_counts(base.replace(H=H), seed=s).a.H).ravel()
                        for s in range(30)])
    assert a.mean() == pytest.approx(5.0, abs=0.03)          # 192,000 draws
    assert a.var() == pytest.approx(2.5, rel=0.03)
    assert a.min() >= 0 and a.max() <= 10


def test_scaled_counts_of_a_simulated_capture_split_in_counts():
    """A simulated noisy capture stores counts / counts_per_unit: the split is in counts."""
    capture, _ = _counts_capture(20.0)
    scale = 250.0
    info = {**capture.scene_info, "noise": {"model": "poisson", "counts_per_unit": scale}}
    scaled = capture.replace(H=(np.asarray(capture.H) / scale).astype(np.float32),
                             scene_info=info)
    assert count_scale(scaled) == scale
    assert np.array_equal(capture_counts(scaled, "x"), np.asarray(capture.H).astype(np.int64))
    halves = split_counts(scaled, seed=0)
    assert halves.count_scale == scale
    total = np.asarray(halves.a.H, dtype=np.float64) + np.asarray(halves.b.H, dtype=np.float64)
    assert np.allclose(total * scale, capture.H, atol=1e-3)
    assert np.allclose(count_variance(halves.b), np.asarray(halves.b.H, dtype=np.float64) / scale)


# ---------------------------------------------------------------- refusals
@pytest.mark.parametrize("H, why", [
    (np.full((256, 4, 4), 0.37, dtype=np.float32), "not integer photon counts"),
    (np.full((256, 4, 4), -2.0, dtype=np.float32), "negative values"),
    (np.where(np.arange(256)[:, None, None] == 100, 2.5, 3.0) * np.ones((256, 4, 4),
                                                                       dtype=np.float32),
     "0.5 from the nearest integer"),
])
def test_what_is_not_counts_is_refused_naming_the_capture(H, why):
    capture = tiny_capture(resolution=4, bins=256).replace(H=H)
    with pytest.raises(ConfigError, match=why) as err:
        split_counts(capture, seed=0, where="scan.hdf5")
    assert err.value.option == "split.count_splitting" and "scan.hdf5" in str(err.value)


def test_background_subtraction_is_refused_with_count_splitting():
    with pytest.raises(ConfigError, match="capture.background") as err:
        run_settings({"split": {"count_splitting": True}, "capture": {"background": "bg.hdf5"}})
    assert err.value.option == "split.count_splitting"


def test_a_float_capture_file_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    capture = tiny_capture(resolution=8)                    # analytic: float radiance
    path = tmp_path / "radiance.hdf5"
    write_capture(path, capture)
    status = main([f"capture.path={path}", "split.count_splitting=true", "model=interp"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("error: split.count_splitting: ") and str(path) in err
    assert "not integer photon counts" in err and err.count("\n") == 1
    assert not (tmp_path / "outputs").exists()


@pytest.mark.parametrize("option, overrides", [
    ("split.count_splitting", ["split.count_splitting=true", "model=interp"]),
    ("model.likelihood", ["model=rsd_prior", "model.likelihood=poisson"]),   # needs counts too
])
def test_a_simulated_scene_without_photon_noise_is_refused_before_the_run(
        option, overrides, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    status = main(["scene=tiny", *overrides, f"hydra.run.dir={tmp_path / 'run'}"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert err.startswith(f"error: {option}: ") and "scene.noise.model=poisson" in err
    assert not (tmp_path / "run").exists()


class _Windowed(PhasorTransform):
    """A DFT with a time window: |kernel| changes with time (no floor from counts)."""

    def transform(self, capture: Capture) -> PhasorField:
        window = np.hanning(capture.n_bins)[:, None, None]
        return FFTTransform().transform(capture.replace(H=capture.H * window))


class _Squared(PhasorTransform):
    """Not linear in H."""

    def transform(self, capture: Capture) -> PhasorField:
        return FFTTransform().transform(capture.replace(H=np.asarray(capture.H) ** 2))


@pytest.mark.parametrize("transform, why", [(_Windowed(), "weighs time bins unequally"),
                                            (_Squared(), "not linear")])
def test_transforms_whose_floor_is_unknown_are_refused(transform, why):
    capture, _ = _counts_capture(5.0)
    with pytest.raises(ConfigError, match=why) as err:
        field_variance(transform, capture, "odd")
    assert err.value.option == "split.count_splitting"


# ---------------------------------------------------------------- the noise floor
def test_kernel_power_of_the_dft_is_the_bin_width_squared():
    capture, _ = _counts_capture(5.0)
    for transform in (FFTTransform(), WaveletTransform()):
        power = kernel_power(transform, capture)
        assert np.allclose(power, capture.delta_t ** 2, rtol=1e-9)


@pytest.mark.parametrize("transform", [FFTTransform(), WaveletTransform()])
def test_floor_matches_monte_carlo_and_a_perfect_predictor_sits_on_it(transform):
    """Var P_B from B's own counts against the spread of P over 400 independent captures;
    the noise-free field scored against B errs by the floor (its excess is ~0)."""
    first, mu = _counts_capture(3.0, seed=0)
    noise_free = transform.transform(first.replace(H=mu)).values
    rng = np.random.default_rng(11)
    draws = np.stack([transform.transform(first.replace(H=rng.poisson(mu).astype(np.float32)))
                      .values for _ in range(400)])
    empirical = draws.var(axis=0)                           # (F, Y, X), complex variance
    predicted = field_variance(transform, first)            # from one capture's counts
    exact = kernel_power(transform, first)[:, None, None] * mu.sum(axis=0).T[None]
    # the formula with the true mean is the Monte-Carlo variance (400 draws: ~7% per sample,
    # ~1% summed); one capture's counts estimate it
    assert empirical.sum() == pytest.approx(exact.sum(), rel=0.03)
    assert np.median(empirical / exact) == pytest.approx(1.0, abs=0.05)
    assert predicted.sum() == pytest.approx(exact.sum(), rel=0.02)
    mask = np.zeros(first.grid_shape[::-1], dtype=bool)
    mask[::2, ::2] = True
    errors, floors = [], []
    for draw in draws[:100]:
        score = heldout_measurement(noise_free, draw, exact, mask)
        errors.append(score.error)
        floors.append(score.floor)
    assert np.mean(errors) == pytest.approx(np.mean(floors), rel=0.03)
    # one capture: the perfect predictor's excess is small against the floor, negative as
    # often as not (null in dB), and its NMSE within a fraction of a dB of the floor
    one = heldout_measurement(noise_free, draws[0], exact, mask)
    assert abs(one.excess) < 0.1 * one.floor
    assert abs(HeldoutMeasurement.db(one.error) - HeldoutMeasurement.db(one.floor)) < 0.5
    # a predictor as noisy as B (another capture) doubles the error: excess = floor
    pairs = [heldout_measurement(draws[k], draws[k + 1], exact, mask) for k in range(0, 200, 2)]
    assert np.mean([p.excess for p in pairs]) == pytest.approx(
        np.mean([p.floor for p in pairs]), rel=0.05)


# ---------------------------------------------------------------- a run with it
@pytest.fixture(scope="module")
def split_sweep(tmp_path_factory) -> Path:
    """The real-data study's preset on a simulated capture of counts (the tiny scene with
    Poisson noise), one sparsity, interp only, two count-splitting seeds."""
    tmp = tmp_path_factory.mktemp("count-split")
    sweep = tmp / "sweep"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(tmp / "cache"))
        mp.chdir(tmp)
        assert main(["-m", "experiment=sparsity_real", "scene=tiny", "scene.noise.model=poisson",
                     "scene.noise.photons=2e5", "model=interp", "split.spatial_step=2",
                     "sampling=grid", "split.count_splitting_seed=1,2",
                     "transform.n_frequencies=21", "reconstruction.n_depths=4",
                     f"hydra.sweep.dir={sweep}"]) == 0
    return sweep


def test_a_run_with_count_splitting_scores_against_half_b(split_sweep):
    run = split_sweep / "0"
    m = json.loads((run / "metrics.json").read_text())
    assert m["schema_version"] == 10
    halves = m["capture"]["count_splitting"]
    assert halves["seed"] == 1 and halves["count_scale"] > 0
    total = (halves["counts_a"] + halves["counts_b"]) / halves["count_scale"]
    # half A holds about half the photons (binomial: within a few standard deviations)
    n = halves["counts_a"] + halves["counts_b"]
    assert abs(halves["counts_a"] - n / 2) < 5 * math.sqrt(n / 4)
    assert m["capture"]["total"] == pytest.approx(halves["counts_a"] / halves["count_scale"],
                                                  rel=1e-4)
    assert total > m["capture"]["total"]
    held = m["field"]["interp"]["splits"]["heldout_measurement"]
    assert held["floor_db"] < held["nmse_db"] < 10
    excess = 10 ** (held["nmse_db"] / 10) - 10 ** (held["floor_db"] / 10)
    assert held["excess"] == pytest.approx(excess, rel=1e-6)
    assert held["excess_db"] == pytest.approx(10 * math.log10(excess), abs=1e-6)
    sources = m["reconstruction"]["sources"]
    assert list(sources) == ["true", "raw", "ceiling", "interp"]
    assert sources["true"]["ssim"] == pytest.approx(1.0)
    assert sources["ceiling"]["ssim"] < 1.0 and math.isfinite(sources["ceiling"]["psnr"])


def test_the_study_report_shows_the_excess_and_the_ceiling(split_sweep):
    assert main(["report", str(split_sweep)]) == 0
    report = split_sweep / "report"
    rows = list(csv.DictReader((report / "study.csv").open()))
    by_series = {r["series"]: r for r in rows}
    assert set(by_series) == {"true", "ceiling", "raw", "interp"}
    interp = by_series["interp"]
    assert interp["runs"] == "2" and interp["seeds"] == "1 2"
    runs = [json.loads((split_sweep / k / "metrics.json").read_text()) for k in ("0", "1")]
    excess = [r["field"]["interp"]["splits"]["heldout_measurement"]["excess_db"] for r in runs]
    assert float(interp["heldout_excess_db_mean"]) == pytest.approx(np.mean(excess), rel=1e-4)
    ceiling = [r["reconstruction"]["sources"]["ceiling"]["psnr"] for r in runs]
    assert float(by_series["ceiling"]["psnr_mean"]) == pytest.approx(np.mean(ceiling), rel=1e-4)
    assert by_series["ceiling"]["heldout_excess_db_mean"] == ""
    text = (report / "report.md").read_text()
    assert "held-out excess (dB)" in text and "Count splitting" in text


def test_the_study_script_collects_the_study_with_its_verdicts(split_sweep, tmp_path):
    """studies/sparse_scans_measured/run.py collect: the JSON holds the study's rows, the
    markdown its table (labelled as a reduced run) and the verdict against interp."""
    out = tmp_path / "real.json"
    script = ROOT / "studies" / "sparse_scans_measured" / "run.py"
    result = subprocess.run([sys.executable, str(script),
                             "collect", str(split_sweep), "--reduced", "--out", str(out),
                             "--ran-on", "<b>[a GPU](x)</b> | y"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=600,
                            check=False)
    assert result.returncode == 0, result.stderr
    results = json.loads(out.read_text())
    assert results["reduced"] is True and results["completed"] == 2
    rows = {r["series"]: r for r in results["rows"]}
    runs = [json.loads((split_sweep / k / "metrics.json").read_text()) for k in ("0", "1")]
    floor = [r["field"]["interp"]["splits"]["heldout_measurement"]["floor_db"] for r in runs]
    assert rows["interp"]["scores"]["heldout_floor_db"]["mean"] == pytest.approx(
        np.mean(floor), rel=1e-6)
    assert "**Reduced run**" in result.stdout
    assert "| ceiling |" in result.stdout and "| interp |" in result.stdout
    # --ran-on is the user's text: escaped for Markdown (no raw HTML, no link, no cell break)
    assert r"on &lt;b&gt;\[a GPU\](x)&lt;/b&gt; \| y. " in result.stdout
    assert "<b>" not in result.stdout and "[a GPU](x)" not in result.stdout


@pytest.mark.skipif(not (REAL / "data_diffuse_s.mat").is_file(),
                    reason="../shared/data/real (the measured captures) is absent")
def test_the_measured_lct_capture_is_photon_counts():
    from scipy.io import loadmat

    counts = np.asarray(loadmat(REAL / "data_diffuse_s.mat")["rect_data"])
    base = tiny_capture(resolution=4, bins=counts.shape[2])
    sample = counts[:4, :4, :].transpose(2, 0, 1).astype(np.float32)
    halves = split_counts(base.replace(H=sample), seed=0)
    assert halves.counts_a + halves.counts_b == int(sample.sum())

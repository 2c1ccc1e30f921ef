"""The studies rebuild their own pages: ``render`` of every study, run on a copy of
``studies/``, writes exactly the committed pages (each study's README.md and the index
studies/README.md), from the committed results.json alone. Figures are redrawn too; their
bytes are not compared (they depend on the matplotlib and font versions), only that each
page's figure is written."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STUDIES = ROOT / "studies"
NAMES = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
         "physics_terms_measured", "classical_imagers_measured")


def _render(copy: Path, name: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(copy / name / "run.py"), "render",
                           "--into", str(copy / name)], capture_output=True, text=True,
                          timeout=300, check=False, cwd=copy.parent)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of studies/ without its pages' generated sections and figures, rendered."""
    copy = tmp_path_factory.mktemp("studies") / "studies"
    shutil.copytree(STUDIES, copy, ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, str(copy))
    try:
        import pages
    finally:
        sys.path.remove(str(copy))
    for page in [copy / "README.md", *(copy / n / "README.md" for n in NAMES)]:
        pages.replace_generated(page, "(emptied by the test)")
    for figure in copy.glob("*/figure.*"):
        figure.unlink()
    for name in NAMES:
        done = _render(copy, name)
        assert done.returncode == 0, f"{name}: {done.stderr[-2000:]}"
    return copy


def test_the_study_folders_are_the_five_questions():
    found = sorted(p.name for p in STUDIES.iterdir() if (p / "run.py").is_file())
    assert found == sorted(NAMES)
    for name in NAMES:
        assert {"README.md", "run.py", "results.json"} <= {p.name for p in
                                                           (STUDIES / name).iterdir()}


@pytest.mark.parametrize("name", NAMES)
def test_render_reproduces_the_committed_page_byte_for_byte(rendered, name):
    committed = (STUDIES / name / "README.md").read_bytes()
    assert (rendered / name / "README.md").read_bytes() == committed, (
        f"studies/{name}/README.md differs from what `run.py render` writes: run "
        f"`python studies/{name}/run.py render` and commit the page")
    figures = list((rendered / name).glob("figure.*"))
    assert len(figures) == 1 and figures[0].stat().st_size > 1000
    assert f"]({figures[0].name})" in committed.decode("utf-8")


def test_the_index_is_generated_from_every_studys_results(rendered):
    index = (rendered / "README.md").read_text(encoding="utf-8")
    assert index == (STUDIES / "README.md").read_text(encoding="utf-8")
    for name in NAMES:
        recorded = json.loads((STUDIES / name / "results.json").read_text())["recorded"]
        row = next(line for line in index.splitlines() if line.startswith(f"| [{name}]"))
        assert row.endswith(f"| {recorded['date']} | {recorded['commit']} | "
                            f"{recorded['machine']} |")


@pytest.mark.parametrize("name", NAMES)
def test_every_results_file_says_where_and_when_it_was_measured(name):
    results = json.loads((STUDIES / name / "results.json").read_text(encoding="utf-8"))
    assert results["question"] and results["source"]
    assert all(results["recorded"][k] for k in ("machine", "commit", "date"))


def test_a_page_without_its_markers_is_refused(tmp_path):
    sys.path.insert(0, str(STUDIES))
    try:
        import pages
    finally:
        sys.path.remove(str(STUDIES))
    page = tmp_path / "README.md"
    page.write_text("# a page\n")
    with pytest.raises(SystemExit, match="markers"):
        pages.replace_generated(page, "text")
    assert page.read_text() == "# a page\n"
    with pytest.raises(ValueError, match="recorded"):
        pages.write_results(tmp_path, {"recorded": {"machine": "m"}})
    assert not (tmp_path / "results.json").exists()


def test_collect_reads_the_scores_the_runs_recorded(tmp_path, monkeypatch):
    """A study's collect copies each score from the run's metrics.json (it computes none):
    the physics study's calibration row of a tiny jittered run holds exactly the run's
    reconstruction scores, labelled by the run's own overrides."""
    import nlosfw

    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    out = nlosfw.run(["scene=tiny", "scene.noise.model=poisson", "scene.noise.jitter_ps=50",
                      "split.spatial_step=2", "model=rsd_prior", "figures.enabled=false",
                      "reconstruction.single_frequency_images=0"], output_dir=tmp_path / "0")
    done = subprocess.run([sys.executable, str(STUDIES / "physics_terms_measured" / "run.py"),
                           "collect", str(out.dir), "--out", str(tmp_path / "r.json")],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads((tmp_path / "r.json").read_text())
    (case,) = results["calibration"]["cases"]
    assert case["case"] == "tiny/analytic/poisson/jitter50ps" and case["step"] == 2
    sources = json.loads((out.dir / "metrics.json").read_text())["reconstruction"]["sources"]
    for name, source in (("raw", "raw"), ("interp", "interp"), ("rsd_prior", "model")):
        for score in ("psnr", "ssim", "volume_psnr", "volume_ssim", "depth_rmse_m"):
            assert case["scores"][name][score] == sources[source][score]
    assert results["rows"] == [] and "| tiny/analytic/poisson/jitter50ps |" in done.stdout
    assert (STUDIES / "physics_terms_measured" / "README.md").is_file()


def _study_module(name: str):
    """A study's run.py as a module (its folder's helpers importable)."""
    import importlib.util

    sys.path.insert(0, str(STUDIES))
    try:
        spec = importlib.util.spec_from_file_location(f"study_{name}", STUDIES / name / "run.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(STUDIES))
    return module


def _study_runs() -> list[list[str]]:
    """Every run the studies' simulated cases, tuning grids and field models would start
    (a tuning sweep's scene axis as one of its scenes)."""
    physics = _study_module("physics_terms_measured")
    thesis = _study_module("thesis_reproduction")
    sparse = _study_module("sparse_scans_simulated")
    runs = physics.simulated_overrides(True, ",".join(physics.SIMULATED))
    runs += [thesis.field_model_overrides(variant, model) for variant in thesis.FIELD_VARIANTS
             for model in thesis.FIELD_MODELS]
    runs += [["experiment=sparsity", *(f"scene={sparse.TUNING_SCENES[0]}"
                                       if o.startswith("scene=") else o
                                       for o in sparse.tuning_overrides(candidate, []))]
             for grid in sparse.TUNING_GRIDS.values() for candidate in grid]
    return runs


def test_every_run_a_study_would_start_is_a_valid_configuration():
    """The runs ``run --simulated``, ``run --field-models`` and ``run --tuning`` start are
    configurations nlosfw accepts: each composes and plans (a misspelt option, such as a
    network's old option name, fails here rather than hours into a study)."""
    from nlosfw.common.errors import ConfigError, PluginError
    from nlosfw.compose import compose_run_config
    from nlosfw.plugins import load_plugins

    host = load_plugins()
    runs = _study_runs()
    # 6 calibration + 10 judged + 8 tuning runs, 8 field models x 2 captures, 13 candidates
    assert len(runs) == 24 + 16 + 13
    planned = 0
    for overrides in runs:
        try:
            config = compose_run_config(overrides, host)
        except PluginError:  # a backend that is not installed here (torch, JAX)
            continue
        planned += 1
        for override in overrides:
            key, _, value = override.partition("=")
            if key.startswith(("model.", "scene.noise.", "split.")):
                node: object = config
                for part in key.split("."):
                    node = node[part]  # type: ignore[index]
                assert str(node).lower() == value.lower() or float(node) == float(value), (
                    override, node)
    assert planned >= 1
    with pytest.raises(ConfigError, match="sigmax"):
        compose_run_config(["model=interp", "model.sigmax=1"], host)


def _row(condition: str, under: float, series: str, kind: str, **scores: float) -> dict:
    return {"condition": condition, "pattern": "grid", "undersampling": under,
            "train_samples": 1, "series": series, "kind": kind, "runs": 3, "seeds": [0, 1, 2],
            "scores": {k: {"n": 3, "mean": v, "std": 0.0, "min": v, "max": v}
                       for k, v in scores.items()}}


def _results(rows: list, runs: int, fits: dict, date: str) -> dict:
    return {"rows": rows, "runs": runs, "completed": runs, "sweeps": [f"/runs/{date}"],
            "overrides": {"model": sorted(fits)}, "ran_on": f"machine of {date}",
            "recorded": {"machine": f"machine of {date}", "commit": "c" + date, "date": date},
            "fit_seconds": {m: {"mean": t, "max": t, "runs": runs} for m, t in fits.items()}}


def test_added_runs_keep_every_committed_number():
    """``collect --add-to``: the committed rows keep their numbers and gain only the scores
    they lacked; the new model's rows join their cells; the added runs' own interp is kept
    apart for the default's comparison; run counts and fit times add up."""
    sys.path.insert(0, str(STUDIES))
    try:
        import sweeps
    finally:
        sys.path.remove(str(STUDIES))
    base = _results([_row("a.mat", 16, "interp", "baseline", psnr=19.0, volume_psnr=22.3),
                     _row("a.mat", 16, "nv", "model", psnr=18.9),
                     _row("a.mat", 64, "interp", "baseline", psnr=16.0)], 6, {"nv": 30.0},
                    "d1")
    added = _results([_row("a.mat", 16, "interp", "baseline", psnr=19.1, volume_psnr=22.1,
                           scale_invariant_psnr=19.3),
                      _row("a.mat", 16, "ens", "model", psnr=19.8),
                      _row("a.mat", 4, "ens", "model", psnr=21.0)], 2, {"ens": 100.0, "nv": 60.0},
                     "d2")
    before = json.dumps(base, sort_keys=True)
    merged = sweeps.add_runs(base, added)
    assert json.dumps(base, sort_keys=True) == before               # nothing of base mutated
    rows = [(r["undersampling"], r["series"]) for r in merged["rows"]]
    assert rows == [(16, "interp"), (16, "nv"), (16, "ens"), (64, "interp"), (4, "ens")]
    interp = merged["rows"][0]["scores"]
    assert interp["psnr"]["mean"] == 19.0 and interp["volume_psnr"]["mean"] == 22.3
    assert interp["scale_invariant_psnr"]["mean"] == 19.3
    (addition,) = merged["additions"]
    assert [r["series"] for r in addition["paired_rows"]] == ["interp"]
    assert addition["paired_rows"][0]["scores"]["volume_psnr"]["mean"] == 22.1
    assert merged["runs"] == 8 and merged["fit_seconds"]["nv"] == {"mean": 37.5, "max": 60.0,
                                                                   "runs": 8}
    assert merged["recorded"]["date"] == "d1; added (ens): d2"
    assert sweeps.shared_score_differences(base, added) == pytest.approx(
        {"psnr": 0.1, "volume_psnr": 0.2})
    with pytest.raises(SystemExit, match="/runs/d2: its runs are in the results already"):
        sweeps.add_runs(merged, added)


def test_a_changed_models_runs_replace_its_earlier_addition():
    """``collect --add-to --replace``: the earlier addition of the same model is withdrawn
    (its rows, its runs' interp, sweeps, counts, fit times and text), then the new runs are
    added: the committed numbers of the other sources stay, the model's are the new runs'."""
    sys.path.insert(0, str(STUDIES))
    try:
        import sweeps
    finally:
        sys.path.remove(str(STUDIES))
    base = _results([_row("a.mat", 16, "interp", "baseline", psnr=19.0),
                     _row("a.mat", 16, "nv", "model", psnr=18.9)], 6, {"nv": 30.0}, "d1")
    first = _results([_row("a.mat", 16, "interp", "baseline", psnr=19.1),
                      _row("a.mat", 16, "ens", "model", psnr=19.8)], 3, {"ens": 100.0}, "d2")
    second = _results([_row("a.mat", 16, "interp", "baseline", psnr=19.2),
                       _row("a.mat", 16, "ens", "model", psnr=20.4)], 3, {"ens": 90.0}, "d3")
    merged = sweeps.add_runs(base, first)
    before = json.dumps(merged, sort_keys=True)
    withdrawn = sweeps.withdraw_addition(merged, ["ens"])
    assert json.dumps(merged, sort_keys=True) == before             # nothing mutated
    for key in ("rows", "runs", "completed", "sweeps", "fit_seconds", "recorded", "ran_on"):
        assert withdrawn[key] == base[key], key
    assert withdrawn["additions"] == []
    replaced = sweeps.add_runs(withdrawn, second)
    assert [(r["series"], r["scores"]["psnr"]["mean"]) for r in replaced["rows"]] == [
        ("interp", 19.0), ("nv", 18.9), ("ens", 20.4)]
    (addition,) = replaced["additions"]
    assert addition["paired_rows"][0]["scores"]["psnr"]["mean"] == 19.2
    assert replaced["runs"] == 9 and replaced["fit_seconds"]["ens"]["mean"] == 90.0
    assert replaced["recorded"]["date"] == "d1; added (ens): d3"
    with pytest.raises(SystemExit, match="nv: no one earlier addition"):
        sweeps.withdraw_addition(merged, ["nv"])


def test_the_default_is_judged_against_the_best_model_and_its_own_runs_interp():
    """The page's default-model table: its excess behind the best of rsd_prior, the residual
    and the neural volume, and its gains against interp scored in its own runs (the paired
    row), not against the committed interp, and a cell meets all four targets or not."""
    study = _study_module("sparse_scans_measured")
    sys.path.insert(0, str(STUDIES))
    try:
        import sweeps
    finally:
        sys.path.remove(str(STUDIES))
    cell = [_row("a.mat", 16, "interp", "baseline", heldout_excess_db=-2.0, psnr=19.0,
                 ssim=0.50, volume_psnr=22.3),
            _row("a.mat", 16, "rsd_prior", "model", heldout_excess_db=-4.0),
            _row("a.mat", 16, "neural_volume_torch", "model", heldout_excess_db=-12.0),
            _row("a.mat", 16, study.DEFAULT_MODEL, "model", heldout_excess_db=-11.8,
                 psnr=20.1, ssim=0.53, scale_invariant_psnr=20.5, volume_psnr=25.0)]
    own = _row("a.mat", 16, "interp", "baseline", heldout_excess_db=-2.0, psnr=19.0,
               ssim=0.50, scale_invariant_psnr=19.5, volume_psnr=22.0)
    rows = sweeps.study_rows_of({"rows": cell})
    paired = sweeps.paired_rows_of({"additions": [{"paired_rows": [own]}]})
    (found,) = study.default_verdicts(rows, paired)
    assert found["best_compared"] == "neural_volume_torch"
    assert found["behind_best_db"] == pytest.approx(0.2)
    assert found["excess_gain_db"] == pytest.approx(9.8)
    assert found["psnr_gain_db"] == pytest.approx(1.1) and found["ssim_gain"] == pytest.approx(0.03)
    assert found["si_psnr_gain_db"] == pytest.approx(1.0)
    assert found["volume_psnr_gain_db"] == pytest.approx(3.0)          # against its own runs
    assert study._met(found) == "yes"
    assert study._met({**found, "psnr_gain_db": 0.9}) == "no"
    assert study._met({**found, "behind_best_db": 0.6}) == "no"
    assert study.default_verdicts(rows)[0]["volume_psnr_gain_db"] == pytest.approx(2.7)


def test_the_studys_default_model_is_the_experiments():
    """The page judges the model that ``experiment=sparsity_real`` runs by default."""
    import yaml

    config = yaml.safe_load((ROOT / "conf" / "experiment" / "sparsity_real.yaml").read_text())
    (model,) = [d["override /model"] for d in config["defaults"] if "override /model" in d]
    assert model == _study_module("sparse_scans_measured").DEFAULT_MODEL

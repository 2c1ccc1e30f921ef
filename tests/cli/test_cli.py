"""The command line: user errors (one line, exit 2, nothing written) and runs end to end."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from nlosfw.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"
QUICK = ["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false"]


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


def run_cli(args, capsys):
    status = main(args)
    out = capsys.readouterr()
    return status, out.out, out.err


def nlosfw(*args, cwd, env=None, check=True):
    """``python -m nlosfw ARGS`` in a subprocess (as a user runs it)."""
    full_env = {**os.environ, "COLUMNS": "200", **(env or {})}
    result = subprocess.run([sys.executable, "-m", "nlosfw", *args], cwd=cwd, env=full_env,
                            capture_output=True, text=True, timeout=600, check=False)
    if check and result.returncode != 0:
        raise AssertionError(f"exit {result.returncode}\n{result.stdout}\n{result.stderr}")
    return result


def bad_capture(tmp_path, edit):
    path = tmp_path / "bad.hdf5"
    shutil.copy(DATA / "ytal_single.hdf5", path)
    with h5py.File(path, "a") as f:
        edit(f)
    return path


def set_nan(f):
    H = f["H"][()]
    H[0, 0, 0] = np.inf
    del f["H"]
    f["H"] = H


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["model=nope"], "error: unknown model plugin 'nope'; valid: "),
        (["scene=nope"], "error: unknown scene 'nope'; valid: "),
        (["-m", "model=interp,nope"], "error: unknown model plugin 'nope'; valid: "),
        (["simulator=analytic", "simulator.patch_size=-1"],
         "error: simulator.patch_size: must be > 0 metres, got -1.0"),
        (["+simulator.bogus=1"], "error: simulator.bogus: unknown option; valid options: "),
        (["model=interp", "split.spatial_step=0"], "error: split.spatial_step: must be >= 1"),
        (["model=interp", "split.spatial_fraction=0.3"],
         "error: split.spatial_fraction: applies to pattern random only"),
        (["model=interp", "split.pattern=random", "split.spatial_fraction=1.5"],
         "error: split.spatial_fraction: must be in (0, 1] or null, got 1.5"),
        (["split.pattern=spiral"], "error: split.pattern: must be one of 'grid', 'random', "
                                   "got 'spiral'"),
        (["acquisition=dirty"], "error: unknown acquisition 'dirty'; valid: clean, noisy"),
        (["scene.time.bins=0"], "error: scene.time.bins: must be a positive number of bins, "
                                "got 0"),
        (["scene.time.bin_width=-0.01"], "error: scene.time.bin_width: must be a positive"),
        (["scene=tiny", "scene.geometry.0.position=[0,0,-0.5]"],
         "error: scene.geometry[0]: rectangle reaches z = -0.5 m; hidden geometry must lie in "
         "front of the wall (z > 0)"),
        (["scene=tiny", "scene.time.start=50"], "error: scene.time: the window [50, 54.1) m"),
        (["capture.path=missing.hdf5"], "error: capture.path: file not found: missing.hdf5"),
        (["stop_after=everything"], "error: stop_after: must be one of"),
        # checked by Hydra as it composes, against the structured configs
        (["model=interp", "model.steps=abc"], "error: model.steps: unknown option; valid "
                                              "options: demodulate, device, extrapolation"),
        (["model.steps=abc"], "error: model.steps: must be an integer, got 'abc' (str)"),
        (["model=interp", "model.extrapolation=linear"],
         "error: model.extrapolation: must be one of 'nearest', 'cubic', got 'linear'"),
        (["figures.dpi=abc"], "error: figures.dpi: must be an integer, got 'abc' (str)"),
        (["scene.geometry.0.albedo=abc"],
         "error: scene.geometry[0].albedo: must be a number, got 'abc' (str)"),
        (["scene.geometry=[{type:point,position:[0,0,1],albedo:x}]"],
         "error: scene.geometry: albedo: must be a number, got 'x' (str)"),
        (["-m", "model=interp", "split.spectral=tail,bogus"],
         "error: split.spectral: must be one of 'interleaved', 'tail', 'none', got 'bogus'"),
        (["compare.pe.steps=3"], "error: compare.pe: not in the config (to add it, start the "
                                 "override with +)"),
        (["+compare.pe={name:pe_torch,steps:abc}"],
         "error: compare.pe.steps: must be an integer, got 'abc' (str)"),
        (["model.lr=nan"], "error: model.lr: must be a number, got NaN"),
        (["-m", "--cfg", "job"], "error: command line: Only one of --run, --multirun, --cfg, "
                                 "--info and --shell_completion can be specified"),
    ],
)
def test_user_errors_one_line_exit_2_nothing_written(workdir, capsys, args, message):
    status, out, err = run_cli(args, capsys)
    assert status == 2
    assert err.startswith(message), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


def test_hydra_refuses_its_own_flags_with_exit_2_and_nothing_written(workdir, capsys):
    """nlosfw reads none of Hydra's flags: a bad one is Hydra's argparse error (its usage
    and one error line), exit status 2, before anything is written."""
    status, out, err = run_cli(["--cfg", "bogus"], capsys)
    assert status == 2
    assert err.splitlines()[-1].endswith(
        "error: argument --cfg/-c: invalid choice: 'bogus' (choose from 'job', 'hydra', 'all')")
    assert "Traceback" not in err
    assert not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (set_nan, "H: contains 1 NaN or inf values out of 1536"),
        (lambda f: f.__delitem__("delta_t"), "missing field 'delta_t'"),
        (lambda f: (f.__delitem__("delta_t"), f.create_dataset("delta_t", data=-1.0)),
         "delta_t: must be a positive number of metres, got -1.0"),
    ],
)
def test_bad_capture_files_are_refused_before_any_output(workdir, capsys, edit, message):
    path = bad_capture(workdir, edit)
    status, _, err = run_cli([f"capture.path={path}", *QUICK[1:]], capsys)
    assert status == 2
    assert err.startswith(f"error: {path}: {message}"), err
    assert not (workdir / "outputs").exists()


def test_truncated_capture_file(workdir, capsys):
    path = workdir / "cut.hdf5"
    data = (DATA / "ytal_single.hdf5").read_bytes()
    path.write_bytes(data[: len(data) // 3])
    status, _, err = run_cli([f"capture.path={path}", *QUICK[1:]], capsys)
    assert status == 2 and err.startswith(f"error: {path}: ") and err.count("\n") == 1


def test_debug_shows_the_traceback(workdir, capsys, monkeypatch):
    # main() sets both for the rest of the process; let monkeypatch restore them afterwards
    monkeypatch.setenv("NLOSFW_DEBUG", "0")
    monkeypatch.setenv("HYDRA_FULL_ERROR", "0")
    status, _, err = run_cli(["--debug", "model=nope"], capsys)
    assert status == 2 and "Traceback" in err and "unknown model plugin 'nope'" in err


def test_plus_group_selects_like_plain_group(workdir, capsys):
    """``+simulator=x`` works although the group has a default (Hydra alone refuses it)."""
    status, out, err = run_cli(["+simulator=analytic", "+model=interp", "--cfg", "job"], capsys)
    assert status == 0, err
    assert "name: analytic" in out and "name: interp" in out


def test_readme_plus_group_command_as_written(workdir, capsys):
    pytest.importorskip("embreex")
    pytest.importorskip("torch")
    status, out, err = run_cli(["+simulator=embree", "+model=siren_torch", "--cfg", "job"],
                               capsys)
    assert status == 0, err
    assert "name: embree" in out and "name: siren_torch" in out
    assert "sampler: sobol" in out and "omega0_first: 15.0" in out   # the configs' defaults
    assert not (workdir / "outputs").exists()


@pytest.mark.parametrize(("config_name", "overrides", "runs"), [
    ("reproduce", [], 7),
    ("thesis_table4_1", [], 3),
    ("config", ["experiment=noise_study"], 5),
    ("config", ["hydra/launcher=parallel", "model=interp,nearest"], 2),
    ("config", ["hydra/launcher=slurm_local", "model=interp,nearest"], 2),
])
def test_documented_sweeps_pass_the_preflight(workdir, monkeypatch, config_name, overrides,
                                              runs):
    """Every combination of the documented sweeps composes and validates before any run."""
    pytest.importorskip("embreex")
    pytest.importorskip("torch")
    from nlosfw import compose
    from nlosfw.compose import checks
    from nlosfw.plugins import load_plugins

    host = load_plugins()
    compose.register_configs(host)
    compose.ensure_resolvers()
    checked = []
    validate = checks.validate_config
    monkeypatch.setattr(checks, "validate_config",
                        lambda cfg, h: (checked.append(cfg), validate(cfg, h)))
    compose.preflight(overrides, host, config_name, multirun=True)
    assert len(checked) == runs
    assert not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


ALL_ARTEFACTS = "output.keep=[capture,phasor_field,fields,model,reconstructions]"


def test_full_run_writes_documented_artefacts(workdir):
    # every figure, at a small dpi (rendering them at the default 110 dpi is most of the run)
    result = nlosfw(*QUICK, "figures.enabled=true", "figures.dpi=40", ALL_ARTEFACTS,
                    cwd=workdir)
    (run,) = list((workdir / "outputs").glob("*/*"))
    names = {str(p.relative_to(run)) for p in run.rglob("*") if p.is_file()}
    expected = {"config.yaml", "run.log", "metrics.json", "capture.hdf5", "phasor_field.hdf5",
                "fields/true.hdf5", "fields/raw.hdf5", "fields/interp.hdf5",
                "reconstructions/true.hdf5", "reconstructions/raw.hdf5",
                "reconstructions/interp.hdf5", "figures/reconstructions.png", "report.html"}
    assert expected <= names, expected - names
    assert any(n.startswith("figures/fields_f") for n in names)
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "completed" and metrics["schema_version"] == 10
    assert set(metrics["timings"]) >= {"capture", "transform", "fit", "predict", "reconstruct",
                                       "report", "total"}
    splits = metrics["field"]["interp"]["splits"]
    assert {"heldout_pixels", "heldout_frequencies", "all"} <= set(splits)
    assert splits["all"]["nmse_db"] < -5
    recon = metrics["reconstruction"]["sources"]
    assert recon["true"]["ssim"] == pytest.approx(1.0)
    assert 0.5 < recon["interp"]["ssim"] <= 1.0
    assert "nlosfw run summary" in result.stdout
    assert not list(run.rglob("*.tmp*")), "a temporary file was left behind"


def test_console_shows_a_compact_overview_not_the_config_dump(workdir):
    result = nlosfw(*QUICK, "model.extrapolation=cubic", cwd=workdir)
    out = result.stdout
    head = out[:out.index("full configuration: config.yaml and .hydra/")]
    assert "scene tiny · simulator analytic · transform fft · model interp · imager fft" in out
    # the options that differ from their defaults, and only those (the cache dir comes from
    # the environment, figures.enabled and extrapolation from the command line)
    changed = head.split("changed from the defaults: ")[1].split("\n")[0]
    assert sorted(changed.split(", ")) == sorted([
        "model.extrapolation=cubic", "figures.enabled=false",
        f"cache.dir={workdir / 'cache'}"])
    assert "├──" not in out and "patch_size" not in out        # no config tree
    # the plan says how many reconstructions and why
    assert "→ 9 reconstructions (fft)" in head
    assert ("= 3 fields [true: the reference, raw: the training samples, interp: the "
            "baseline] × (all frequencies + 2 single frequencies (training, held out))") in head
    assert len(head.splitlines()) <= 8, head
    # and the run made exactly those
    (run,) = list((workdir / "outputs").glob("*/*"))
    metrics = json.loads((run / "metrics.json").read_text())["reconstruction"]
    assert len(metrics["sources"]) * (1 + len(metrics["single_frequency"])) == 9
    assert "stage capture" not in out                       # stage timings: run.log only
    assert "stage capture: started" in (run / "run.log").read_text()


def test_output_keep_default_keeps_capture_and_model_and_reports_the_size(workdir):
    result = nlosfw(*QUICK[:1], "model=nearest", *QUICK[2:], cwd=workdir)
    (run,) = list((workdir / "outputs").glob("*/*"))
    names = {str(p.relative_to(run)) for p in run.rglob("*") if p.is_file()}
    assert {"capture.hdf5", "field_model.npz", "metrics.json", "config.yaml"} <= names
    assert not {n for n in names if n.startswith(("fields/", "reconstructions/"))}
    assert "phasor_field.hdf5" not in names
    size = sum(p.stat().st_size for p in run.rglob("*") if p.is_file())
    match = re.search(r"done \(completed\): .*?, ([0-9.]+) (B|kB|MB) \(large files kept: "
                      r"capture, model; not written: phasor_field, fields, reconstructions, "
                      r"see output.keep\)", " ".join(result.stdout.split()))
    assert match, result.stdout[-600:]
    shown = float(match.group(1)) * {"B": 1, "kB": 1e3, "MB": 1e6}[match.group(2)]
    # printed before Hydra's logging closes run.log: within a few percent of the final size
    assert shown == pytest.approx(size, rel=0.05)


def test_output_keep_refuses_unknown_artefacts(workdir, capsys):
    status, _, err = run_cli([*QUICK, "output.keep=[model,figures]"], capsys)
    assert status == 2
    assert err.startswith("error: output.keep[1]: Invalid value 'figures', expected one of "
                          "[capture, phasor_field, fields, model, reconstructions]"), err


def test_library_logging_goes_to_the_log_file_not_the_console(workdir):
    """JAX logs while it starts (its backend probing): run.log has those records, the
    console shows none of them."""
    pytest.importorskip("jax")
    result = nlosfw(*QUICK[:1], "model=siren_jax", "model.steps=20", "model.hidden=[8]",
                    *QUICK[2:], cwd=workdir)
    (run,) = list((workdir / "outputs").glob("*/*"))
    records = re.findall(r"^\[[^]]+\]\[([^]]+)\]\[(\w+)\] (.*)$",
                         (run / "run.log").read_text(), flags=re.MULTILINE)
    foreign = [(name, msg) for name, level, msg in records
               if not name.startswith("nlosfw") and level not in ("ERROR", "CRITICAL")]
    assert any(name.startswith("jax") for name, _ in foreign), records
    console = " ".join((result.stdout + result.stderr).split())
    for _, message in foreign:
        assert " ".join(message.split())[:40] not in console, message


def test_stop_after_and_capture_from_file(workdir):
    nlosfw(*QUICK, "stop_after=simulate", cwd=workdir)
    (run,) = list((workdir / "outputs").glob("*/*"))
    names = {p.name for p in run.iterdir()}
    assert "capture.hdf5" in names and "phasor_field.hdf5" not in names
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "stopped" and metrics["run"]["stopped_after"] == "capture"
    # start a second run from the capture the first one wrote
    nlosfw(f"capture.path={run / 'capture.hdf5'}", *QUICK[1:], "stop_after=transform",
           cwd=workdir)
    second = [r for r in (workdir / "outputs").glob("*/*") if r != run]
    assert len(second) == 1
    metrics = json.loads((second[0] / "metrics.json").read_text())
    assert metrics["capture"]["source"] == "file"
    assert metrics["transform"]["n_frequencies"] > 0


def test_capture_written_by_ytal_runs_through_the_pipeline(workdir):
    nlosfw(f"capture.path={DATA / 'ytal_single.hdf5'}", "model=interp", "stop_after=transform",
           "transform.n_frequencies=9", cwd=workdir)
    (run,) = list((workdir / "outputs").glob("*/*"))
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["capture"]["shape"] == [64, 6, 4]
    assert metrics["transform"]["grid"] == [4, 6]  # the field is [frequency, y, x]


def test_sweep_report_and_resume(workdir, capsys):
    sweep = workdir / "sweep"
    nlosfw("-m", *QUICK[:1], "model=interp,nearest", "imager=fft", "figures.enabled=false",
           f"hydra.sweep.dir={sweep}", cwd=workdir)
    runs = sorted(p.parent for p in sweep.rglob("metrics.json"))
    assert [r.name for r in runs] == ["0", "1"]
    first = (runs[0] / "metrics.json").read_bytes()
    again = nlosfw("-m", *QUICK[:1], "model=interp,nearest", "imager=fft",
                   "figures.enabled=false", f"hydra.sweep.dir={sweep}", cwd=workdir)
    assert again.stdout.count("skipping") == 2
    assert (runs[0] / "metrics.json").read_bytes() == first

    # the report command in-process: the sweep and its resume are the runs a user starts
    status, out, _ = run_cli(["report", str(sweep)], capsys)
    assert status == 0 and "report written to" in out
    csv = (sweep / "report" / "report.csv").read_text().splitlines()
    assert len(csv) == 3 and csv[0].startswith("run,status,scene")
    assert (sweep / "report" / "report.png").stat().st_size > 1000
    assert "## Quality against model" in (sweep / "report" / "report.md").read_text()
    assert "<a href=\"../0/report.html\">0</a>" in (sweep / "report" / "report.html").read_text()
    assert run_cli(["report", str(sweep)], capsys)[0] == 0
    assert (sweep / "report-2" / "report.md").exists()  # the first report is kept


@pytest.mark.slow
def test_non_editable_install_runs_from_any_directory(tmp_path):
    """A plain ``pip install .`` (no editable finder, no source tree) finds its configs."""
    repo = Path(__file__).resolve().parents[2]
    # a copy of what the distribution is built from: building in the checkout would write
    # build/ and nlosfw.egg-info into it while other test processes read its entry points
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(repo / name, source / name)
    for name in ("nlosfw", "conf"):
        shutil.copytree(repo / name, source / name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-cache-dir",
                    "--target", str(target), str(source)], check=True, timeout=600,
                   capture_output=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {"PYTHONPATH": str(target), "NLOSFW_CACHE_DIR": str(tmp_path / "cache")}
    result = nlosfw(*QUICK, "--cfg", "job", cwd=elsewhere, env=env)
    assert "name: interp" in result.stdout
    result = nlosfw(*QUICK, "stop_after=transform", cwd=elsewhere, env=env)
    assert (elsewhere / "outputs").is_dir()
    import_check = subprocess.run(
        [sys.executable, "-c", "import nlosfw.common.resources as r; print(r.config_dir())"],
        cwd=elsewhere, env={**os.environ, **env}, capture_output=True, text=True, check=True)
    assert str(target) in import_check.stdout


@pytest.mark.parametrize("launcher", ["slurm_local", "parallel"])
def test_sweep_through_submitit_and_joblib_launchers(workdir, launcher):
    """The SLURM launcher's code path (submitit's local executor) and the joblib launcher."""
    sweep = workdir / launcher
    nlosfw("-m", f"hydra/launcher={launcher}", *QUICK[:1], "model=interp,nearest",
           "figures.enabled=false", f"hydra.sweep.dir={sweep}", cwd=workdir)
    statuses = [json.loads((sweep / str(i) / "metrics.json").read_text())["status"]
                for i in (0, 1)]
    assert statuses == ["completed", "completed"]
    models = {json.loads((sweep / str(i) / "metrics.json").read_text())["run"]["model"]
              for i in (0, 1)}
    assert models == {"interp", "nearest"}


def test_simulator_specific_refusal_before_any_output(workdir, capsys):
    """A scene the chosen simulator cannot render is refused by preflight (check_scene)."""
    status, _, err = run_cli(["scene=tiny", "scene.geometry.0.type=box",
                              "scene.geometry.0.size=[0.2,0.2,0.2]", "simulator=analytic",
                              "model=interp"], capsys)
    assert status == 2
    assert err.startswith("error: scene.geometry[0].type: the analytic simulator has no "
                          "visibility and supports only point, patch, rectangle, heightfield")
    assert not (workdir / "outputs").exists()

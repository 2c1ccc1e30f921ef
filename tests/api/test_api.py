"""The Python API: ``nlosfw.run`` is the command line's run, and the stage functions
reproduce the pipeline's numbers exactly."""

import json
import subprocess
import sys

import numpy as np
import pytest
import yaml

import nlosfw
from nlosfw.cli import main
from nlosfw.common import one_line
from nlosfw.pipeline.metrics import RunMetrics

TINY = ["scene=tiny", "model=interp", "transform.n_frequencies=21", "reconstruction.n_depths=4",
        "figures.enabled=false"]


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("api")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(root / "cache"))
        return nlosfw.run(TINY, output_dir=root / "run")


def test_run_returns_the_typed_results_and_the_metrics_it_wrote(tiny_run):
    out = tiny_run
    assert out.dir.name == "run" and out.metrics.status == "completed"
    assert out.metrics.to_json() == RunMetrics.read(out.dir / "metrics.json").to_json()
    results = out.results
    assert list(results.reconstructions.by_source) == ["true", "raw", "interp"]
    assert results.fields.true.values.shape == (21, 16, 16)
    assert out.config["scene"]["name"] == "tiny" and out.config["model"]["name"] == "interp"
    assert (out.dir / "config.yaml").is_file() and (out.dir / "run.log").is_file()
    assert "stage reconstruct" in (out.dir / "run.log").read_text()
    assert yaml.safe_load((out.dir / ".hydra" / "overrides.yaml").read_text()) == TINY


def test_stage_functions_reproduce_the_run(tiny_run, workdir):
    """Each stage by hand, through the public functions, gives the run's numbers."""
    run = tiny_run.results
    capture = nlosfw.simulate_scene("tiny")
    np.testing.assert_array_equal(capture.H, run.capture.capture.H)
    field = nlosfw.transform_capture(capture, "fft", n_frequencies=21)
    np.testing.assert_array_equal(field.values, run.transform.field.values)
    split = nlosfw.split_field(field, spatial_step=2)
    model = nlosfw.fit_model(split.train_field, "interp")
    predicted = nlosfw.predict_field(model, field)
    np.testing.assert_array_equal(predicted.values, run.fields.predicted["interp"].values)
    errors = nlosfw.field_metrics(field, predicted, split)["heldout_pixels"]
    expected = tiny_run.metrics.field["interp"].splits.heldout_pixels
    assert errors["nmse_db"] == expected.nmse_db and errors["n_samples"] == expected.n_samples
    depths = tiny_run.metrics.reconstruction.depths
    image = nlosfw.reconstruct(predicted, depths, "fft")
    np.testing.assert_array_equal(image.voxels, run.reconstructions.voxels)
    np.testing.assert_allclose(image.intensity, run.reconstructions.by_source["interp"].intensity,
                               rtol=1e-12, atol=0)
    raw = field.select(y=slice(None, None, 2), x=slice(None, None, 2))   # on the full grid
    image = nlosfw.reconstruct(raw, depths, "fft", grid=field)
    np.testing.assert_allclose(image.intensity, run.reconstructions.by_source["raw"].intensity,
                               rtol=1e-12, atol=0)


def test_depths_of_a_run_cover_the_hidden_scene(tiny_run):
    near, far = nlosfw.depth_span(tiny_run.results.capture.capture)
    np.testing.assert_allclose(tiny_run.metrics.reconstruction.depths,
                               np.linspace(near, far, 4))


@pytest.mark.parametrize("overrides", [
    ["model=nope"],
    ["scene=tiny", "scene.time.bins=0"],
    ["model=interp", "model.extrapolation=linear"],
    ["+compare.pe={name:pe_torch,steps:abc}"],
    ["capture.path=missing.hdf5"],
])
def test_run_raises_the_error_the_command_line_prints(workdir, capsys, overrides):
    with pytest.raises(nlosfw.NlosfwError) as raised:
        nlosfw.run(overrides, output_dir=workdir / "run")
    assert main(overrides) == 2
    assert capsys.readouterr().err == f"error: {one_line(raised.value, whole=True)}\n"
    assert not (workdir / "run").exists() and not (workdir / "outputs").exists()


@pytest.mark.parametrize(("overrides", "message"), [
    (["model=interp,nearest"], "overrides: 'model=interp,nearest' is a sweep"),
    (["--cfg", "job"], "overrides: '--cfg' is a command-line flag"),
    (["hydra.run.dir=x"], "overrides: 'hydra.run.dir=x': Hydra's own settings do not apply"),
    ("model=interp", "overrides: expected a list of overrides, got the string 'model=interp'"),
])
def test_run_refuses_what_one_call_cannot_do(workdir, overrides, message):
    with pytest.raises(nlosfw.ConfigError) as raised:
        nlosfw.run(overrides, output_dir=workdir / "run")
    assert str(raised.value).startswith(message), raised.value
    assert not (workdir / "run").exists()


def test_run_never_writes_into_a_directory_holding_files(workdir):
    (workdir / "run").mkdir()
    (workdir / "run" / "notes.txt").write_text("mine")
    with pytest.raises(nlosfw.ConfigError, match=r"output_dir: .* already holds files"):
        nlosfw.run(TINY, output_dir=workdir / "run")
    assert [p.name for p in (workdir / "run").iterdir()] == ["notes.txt"]


def test_run_stopped_early_has_the_stages_that_ran(workdir):
    out = nlosfw.run([*TINY, "stop_after=transform"], output_dir=workdir / "run")
    assert out.metrics.status == "stopped" and out.metrics.run.stopped_after == "transform"
    assert out.stages.transform is not None and out.stages.fit is None
    with pytest.raises(nlosfw.DataError, match="stopped after transform"):
        _ = out.results


def test_run_without_output_dir_writes_a_new_temporary_directory(workdir):
    out = nlosfw.run([*TINY, "stop_after=capture"])
    try:
        assert out.dir.is_dir() and out.dir.name.startswith("nlosfw-run-")
        assert (out.dir / "capture.hdf5").is_file() and not (workdir / "outputs").exists()
    finally:
        import shutil

        shutil.rmtree(out.dir)


def test_stage_functions_check_options_like_the_command_line():
    capture = nlosfw.simulate_scene("tiny")
    with pytest.raises(nlosfw.ConfigError, match="n_frequencies"):
        nlosfw.transform_capture(capture, "fft", n_frequencies=0)
    with pytest.raises(nlosfw.ConfigError, match="bogus: unknown option"):
        nlosfw.transform_capture(capture, "fft", bogus=1)
    with pytest.raises(nlosfw.ConfigError, match="unknown scene 'nope'"):
        nlosfw.simulate_scene("nope")
    field = nlosfw.transform_capture(capture, n_frequencies=5)
    with pytest.raises(nlosfw.ConfigError, match="depths: need one or more finite depths > 0"):
        nlosfw.reconstruct(field, [0.5, -1.0])


def test_importing_nlosfw_loads_no_hydra_matplotlib_or_backend():
    heavy = ("hydra", "omegaconf", "matplotlib", "rich", "torch", "jax", "mitsuba", "embreex")
    code = ("import json, sys, nlosfw\n"
            f"print(json.dumps([m for m in {heavy!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)
    assert json.loads(out.stdout) == []

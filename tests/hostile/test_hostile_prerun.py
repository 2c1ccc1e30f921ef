"""Every option is checked before the run, and a failing check stops it: an out-of-range
seed, a time window beyond any float, a device the machine does not have, a network
option of a model that wraps a network, an imager the capture's kind cannot feed. Each
ends with one line naming the option as the user spells it, exit status 2, and nothing
written; a pre-run check that itself fails ends the command the same way."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import nlosfw
from nlosfw.capture.hdf5 import write_capture
from nlosfw.common.errors import ConfigError
from nlosfw.compose import checks
from nlosfw.testing.fixtures import tiny_capture

#: A few-second run without its model: the cases choose one (a network, two steps).
TORCH = ("scene=tiny", "imager=fft", "figures.enabled=false", "transform.n_frequencies=21",
         "reconstruction.n_depths=4")


def no_output(workdir: Path) -> bool:
    return not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


def refused(tools, workdir: Path, option: str, *overrides: str) -> str:
    """The one error line of a run of ``overrides`` refused before it started, naming
    ``option``."""
    result = tools.run(*overrides)
    line = tools.one_error_line(result)
    assert result.returncode == 2, result.stderr
    assert line.startswith(f"error: {option}: "), line
    assert no_output(workdir), "the run started"
    assert not (workdir / "cache").exists(), "the run started"
    return line


def capture_file(folder: Path, confocal: bool = False) -> Path:
    path = folder / "scan.hdf5"
    write_capture(path, tiny_capture(resolution=8, confocal=confocal))
    return path


# ------------------------------------------------------------------------------ seeds
def test_a_negative_split_seed_is_refused_before_the_run(tools, workdir):
    line = refused(tools, workdir, "split.seed", *tools.QUICK, "split.pattern=random",
                   "split.seed=-1")
    assert f"0 to {2**63 - 1}" in line and "-1" in line


def test_a_negative_count_splitting_seed_is_refused_before_the_run(tools, workdir):
    refused(tools, workdir, "split.count_splitting_seed", *tools.QUICK, "scene.noise.model=poisson",
            "split.count_splitting=true", "split.count_splitting_seed=-1")


@pytest.mark.parametrize("option", ["split.seed", "split.count_splitting_seed"])
def test_a_negative_seed_is_refused_by_the_python_api(option, workdir):
    out = workdir / "api-run"
    with pytest.raises(ConfigError) as err:
        nlosfw.run([*("scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
                      "scene.noise.model=poisson", "split.pattern=random",
                      "split.count_splitting=true"), f"{option}=-1"], output_dir=out)
    assert err.value.option == option
    assert not out.exists()


@pytest.mark.parametrize(("option", "overrides"), [
    ("model.seed", ["model=interp", "model.seed=-1"]),                 # interp ignores it
    ("simulator.seed", ["model=interp", "simulator.seed=-1", "scene.noise.model=poisson"]),
    ("compare.nn.seed", ["model=interp", "+compare.nn={name:nearest,seed:-3}"]),
    # sizes and counts handed to numpy, matplotlib, thread pools: each ended the run after
    # it had started (out of memory, OverflowError, "lam value too large", a C int)
    ("figures.dpi", ["model=interp", "figures.enabled=true", "figures.dpi=100000"]),
    ("scene.noise.pulses", ["model=interp", "scene.noise.model=poisson",
                            "scene.noise.pulses=100000000000000000000"]),
    ("scene.noise.photons", ["model=interp", "scene.noise.model=poisson",
                             "scene.noise.photons=1e300"]),
    ("scene.noise.dark_counts", ["model=interp", "scene.noise.model=poisson",
                                 "scene.noise.dark_counts=1e17"]),   # its total wrapped
    ("imager.workers", ["model=interp", "imager.workers=100000000000000000000"]),
    ("model.smoothness_points", ["model=siren_torch", "model.steps=2",
                                 "model.frequency_smoothness=1",
                                 "model.smoothness_points=100000000000000000000"]),
    ("model.threads", ["model=siren_torch", "model.steps=2",
                       "model.threads=100000000000000000000"]),
])
def test_other_out_of_range_ints_are_refused_before_the_run(option, overrides, tools,
                                                            workdir):
    refused(tools, workdir, option, *TORCH, *overrides)


def test_a_fourier_encoding_too_large_for_memory_is_refused_before_the_run(tools, workdir):
    """10^11 features: the estimate counted the hidden layers only, and the fit ended in
    torch's allocator."""
    result = tools.run(*TORCH, "model=fourier_torch", "model.steps=2",
                       "model.features=100000000000")
    line = tools.one_error_line(result)
    assert result.returncode == 2
    assert line.startswith("error: this run needs about ") and "model's training" in line
    assert no_output(workdir)


def test_a_seed_beyond_64_bits_is_refused_for_a_jax_network(tools, workdir):
    """JAX's keys take 64-bit seeds: 10^20 ended the fit with an OverflowError."""
    refused(tools, workdir, "model.seed", *TORCH, "model=siren_jax", "model.steps=2",
            "model.seed=100000000000000000000")


# -------------------------------------------------------------------- time windows
def test_a_time_crop_to_1e308_metres_keeps_the_rest_of_the_histogram(tools, workdir):
    """The check computed the last bin as int(1e308 / delta_t): an OverflowError, which
    Hydra turned into a warning and the run went on to crash. The window ends with the
    histogram, as any stop beyond it does."""
    path = capture_file(workdir)
    crops = {}
    for stop in ("1e308", "100"):
        result = tools.run(f"capture.path={path}", *tools.QUICK[1:], "stop_after=capture",
                           f"capture.time_crop.metres=[0.1,{stop}]",
                           f"hydra.run.dir={workdir / stop}")
        assert result.returncode == 0, result.stderr
        assert "Warning" not in result.stderr and "error" not in result.stderr
        metrics = json.loads((workdir / stop / "metrics.json").read_text())
        steps = metrics["capture"]["preprocessing"]
        crops[stop] = [s["effect"] for s in steps if s["option"] == "time_crop"]
    assert crops["1e308"] == crops["100"] == ["kept bins 10 to 255 (path 0.1 to 2.56 m)"]


@pytest.mark.parametrize(("option", "override"), [
    ("capture.time_crop.metres", "capture.time_crop.metres=[1e300,1e308]"),
    ("capture.time_crop.metres", "capture.time_crop.metres=[-1e308,-1e300]"),
    ("capture.gate.metres", "capture.gate.metres=1e308"),
])
def test_time_windows_beyond_any_bin_are_refused_before_the_run(option, override, tools,
                                                                 workdir):
    path = capture_file(workdir)
    refused(tools, workdir, option, f"capture.path={path}", *tools.QUICK[1:], override)


@pytest.mark.parametrize(("option", "override"), [
    ("capture.time_crop.metres", "capture.time_crop.metres=[1e300,1e308]"),
    ("capture.time_crop.bins", "capture.time_crop.bins=[0,99999]"),
    ("capture.gate.bins", "capture.gate.bins=99999"),
    ("capture.bin", "capture.bin=3"),
    ("capture.pileup_pulses", "capture.pileup_pulses=1000"),      # the scene has no counts
])
def test_a_simulated_captures_preprocessing_is_checked_before_the_run(option, override,
                                                                       tools, workdir):
    """The scene states the capture's time axis and scan grid: the options that do not fit
    them are refused before the capture is simulated (they were refused at the capture
    stage, the run directory written)."""
    refused(tools, workdir, option, *tools.QUICK, override)


# ------------------------------------------------------------- a check that fails
@pytest.mark.parametrize("failure", [OverflowError("cannot convert float infinity to "
                                                   "integer"),
                                     KeyError("name"), RuntimeError("a plugin's check\nfailed")])
def test_a_check_that_fails_stops_the_run(failure, tools, workdir, monkeypatch):
    """Hydra turns an exception of a callback into a warning and starts the run anyway:
    a check that cannot decide must end the command instead."""
    def check(cfg, host):
        raise failure

    monkeypatch.setattr(checks, "validate_config", check)
    result = tools.run(*tools.QUICK)
    line = tools.one_error_line(result)
    assert result.returncode == 2
    assert line.startswith("error: the checks before the run failed: "
                           f"{type(failure).__name__}: "), line
    assert "Warning" not in result.stderr
    assert no_output(workdir)


# ---------------------------------------------------------------------------- devices
@pytest.mark.parametrize(("option", "overrides"), [
    ("model.device", ["model=siren_torch", "model.steps=2", "model.device=cuda:7"]),
    ("model.device", ["model=siren_jax", "model.steps=2", "model.device=gpu:7"]),
    ("model.device", ["model=rsd_residual_torch", "model.network_steps=2",
                      "model.device=cuda:7"]),
    ("compare.pe.device", ["model=interp", "+compare.pe={name:pe_torch,steps:2,"
                                           "device:'cuda:7'}"]),
])
def test_a_device_the_machine_lacks_is_refused_before_the_run(option, overrides, tools,
                                                               workdir):
    """Refused at the fit stage before, with the run directory written. (On a machine with
    eight GPUs the first would run: the tests' machines have none.)"""
    line = refused(tools, workdir, option, *TORCH, *overrides)
    assert "cuda:7" in line or "gpu:7" in line


@pytest.mark.parametrize("imager", ["fft", "lct", "fk", "fbp"])
def test_an_imager_on_cuda_without_one_is_refused_before_the_run(imager, tools, workdir):
    """``imager.device=cuda`` on a machine where no array backend sees a CUDA device: one
    line naming the option and what is valid here, before anything is written."""
    import torch

    if torch.cuda.device_count():
        pytest.skip("this machine has a CUDA device: imager.device=cuda runs")
    line = refused(tools, workdir, "imager.device", "scene=tiny", "model=none",
                   "scene.capture.type=confocal", "figures.enabled=false",
                   f"imager={imager}", "imager.device=cuda")
    assert "no CUDA device" in line and "valid here: auto, cpu" in line, line


# --------------------------------------------------------------- network options
@pytest.mark.parametrize(("option", "overrides"), [
    ("model.network_lr", ["model=rsd_residual_torch", "model.network_steps=2",
                          "model.network_lr=inf"]),
    ("model.lr", ["model=neural_volume_torch", "model.steps=2", "model.lr=inf"]),
    ("compare.res.network_lr", ["model=interp", "+compare.res={name:rsd_residual_torch,"
                                                "network_steps:2,network_lr:inf}"]),
    ("compare.vol.lr", ["model=interp", "+compare.vol={name:neural_volume_jax,steps:2,"
                                        "lr:inf}"]),
])
def test_network_options_are_named_as_the_user_spells_them(option, overrides, tools,
                                                           workdir):
    refused(tools, workdir, option, *TORCH, *overrides)


@pytest.mark.parametrize(("named", "overrides"), [
    ("lower model.network_lr", ["model=rsd_residual_torch", "model.network_steps=30",
                                "model.network_lr=1000000.0"]),
    ("lower compare.pe.lr", ["model=interp", "+compare.pe={name:siren_torch,steps:30,"
                                             "eval_every:1,lr:1000000.0,"
                                             "divergence_factor:1.01}"]),
])
def test_a_diverged_fit_names_the_learning_rate_as_the_user_spells_it(named, overrides, tools,
                                                                      workdir):
    """A fit that diverges can only fail in the fit: its one line says which option to
    lower (it said ``model.lr``, an option neither run has)."""
    result = tools.run(*TORCH, *overrides)
    line = tools.one_error_line(result)
    assert result.returncode == 2
    assert "training diverged" in line and f"{named} (now 1e+06)" in line, line


# -------------------------------------------------------------------- capture kinds
@pytest.mark.parametrize("imager", ["lct", "fk", "fbp"])
def test_a_confocal_imager_is_refused_before_simulating_a_single_spot_scene(imager, tools,
                                                                            workdir):
    """Refused when the imager met the field; the same scene scanned confocally runs."""
    line = refused(tools, workdir, "imager", *tools.QUICK, f"imager={imager}")
    assert "single_spot" in line and "confocal" in line
    result = tools.run(*tools.QUICK, f"imager={imager}", "scene.capture.type=confocal",
                       "stop_after=capture", f"hydra.run.dir={workdir / 'run'}")
    assert result.returncode == 0, result.stderr
    assert (workdir / "run" / "metrics.json").is_file()


def test_a_confocal_imager_is_refused_before_reading_on_for_a_single_spot_file(tools,
                                                                               workdir):
    path = capture_file(workdir)
    line = refused(tools, workdir, "imager", f"capture.path={path}", *tools.QUICK[1:],
                   "imager=lct")
    assert str(path) in line


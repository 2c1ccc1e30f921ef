"""Every run leaves its record: degenerate data (a score that cannot be computed is null
with its reason in metrics.json, never a crash writing it), a failure after the last stage
(report.html, the console summary) recorded as such, unexpected failures in one line on
the console, and an output directory that cannot be written refused with exit status 2."""

from __future__ import annotations

import errno
import json
import re
from pathlib import Path

import numpy as np
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import files
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.pipeline.lifecycle import FINISHED, LOCK_NAME, inspect_run_dir
from nlosfw.testing import fixtures

#: The quick run imaging the capture alone (no field model): depth RMSE against the truth.
IMAGE_ONLY = ("scene=tiny", "model=none", "imager=fft", "figures.enabled=false",
              "transform.n_frequencies=21", "reconstruction.n_depths=4")
#: The tiny scene's one patch reflects nothing.
ZERO_ALBEDO = "scene.geometry.0.albedo=0"


def metrics_of(run: Path) -> dict:
    return json.loads((run / "metrics.json").read_text())


def assert_null_with_reason(section: dict, key: str, *words: str) -> str:
    """``section[key]`` is null (present in the JSON) and ``null_reasons`` says why, in one
    line holding each of ``words``; the reason."""
    assert key.split(".")[0] in section and _get(section, key) is None, section
    reason = section["null_reasons"][key]
    assert "\n" not in reason and all(w in reason for w in words), reason
    return reason


def _get(section: dict, dotted: str) -> object:
    node: object = section
    for part in dotted.split("."):
        assert isinstance(node, dict)
        node = node[part]
    return node


# ---------------------------------------------------------------- degenerate data
def test_a_scene_with_zero_albedo_records_its_depth_rmse_as_null_with_its_reason(workdir,
                                                                                 tools):
    result = tools.run(*IMAGE_ONLY, ZERO_ALBEDO, "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    metrics = metrics_of(workdir / "run")
    assert metrics["status"] == "completed" and metrics["capture"]["total"] == 0.0
    true = metrics["reconstruction"]["sources"]["true"]
    assert_null_with_reason(true, "depth_rmse_m", "zero")
    assert_null_with_reason(true, "psnr", "zero")
    assert true["rmse"] == 0.0


def test_an_all_zero_capture_file_with_ground_truth_is_imaged_and_recorded(workdir, tools):
    assert tools.run(*IMAGE_ONLY, "stop_after=capture", "hydra.run.dir=src").returncode == 0
    capture = read_capture(workdir / "src" / "capture.hdf5")
    assert np.any(np.asarray(capture.scene_info["ground_truth"]["depth"]) > 0)
    write_capture(workdir / "zero.hdf5", capture.replace(H=np.zeros_like(capture.H)))
    result = tools.run("image", str(workdir / "zero.hdf5"), "figures.enabled=false",
                       "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    metrics = metrics_of(workdir / "run")
    assert metrics["status"] == "completed"
    assert_null_with_reason(metrics["reconstruction"]["sources"]["true"], "depth_rmse_m",
                            "zero")


def test_poisson_counts_without_dark_counts_records_the_undefined_fit_number(workdir, tools):
    """rsd_prior's counts likelihood with the scene's default of no dark counts: its
    log-likelihood gain is NaN; the run completes with it null and why."""
    result = tools.run("scene=tiny", "model=rsd_prior", "model.likelihood=poisson_counts",
                       "split.spectral=none", "scene.noise.model=poisson", "imager=fft",
                       "figures.enabled=false", "transform.n_frequencies=21",
                       "reconstruction.n_depths=4", "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    metrics = metrics_of(workdir / "run")
    assert metrics["status"] == "completed"
    fit = metrics["field"]["model"]["fit"]
    assert_null_with_reason(fit, "fitted.counts_loglik_gain", "nan")
    assert fit["fitted"]["counts_iterations"] >= 1


def test_a_noisy_scene_with_zero_albedo_records_its_denoising_as_null(workdir, tools):
    """Dark counts alone: the noise-free field is zero, so every error against it (and the
    gain) cannot be computed; the run used to fail with ZeroDivisionError."""
    result = tools.run(*tools.QUICK, ZERO_ALBEDO, "scene.noise.model=poisson",
                       "scene.noise.dark_counts=50", "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    metrics = metrics_of(workdir / "run")
    assert metrics["status"] == "completed"
    denoising = metrics["field"]["interp"]["denoising"]
    for key in ("noisy_relative_l2", "relative_l2", "gain_db"):
        assert_null_with_reason(denoising, key, "noise-free field is zero")
    assert metrics["field"]["interp"]["splits"]["all"]["relative_l2"] > 0


def test_undefined_scores_of_degenerate_images_and_fields_say_why():
    """The functions behind the sections, on zero, constant and empty inputs: every value
    is a finite number or None with a reason, never NaN or inf."""
    from nlosfw.evaluation.image_scores import depth_error, scored
    from nlosfw.pipeline.measure import denoising_metrics
    from nlosfw.pipeline.metrics import SplitErrors

    voxels = fixtures.wall_grid(8)[None].repeat(3, axis=0)
    voxels[..., 2] = np.array([0.3, 0.5, 0.7])[:, None, None]
    zero = Reconstruction(np.zeros((3, 8, 8)), voxels)
    lit = np.zeros((3, 8, 8))
    lit[1, :, :4] = 1.0                                  # the right half is dark
    half = Reconstruction(lit, voxels)
    truth = np.full((8, 8), 0.5)
    values, reasons = scored(half, half, truth)
    assert values["depth_rmse_m"] is None and "32 of the 64" in reasons["depth_rmse_m"]
    assert values["psnr"] is None and "identical" in reasons["psnr"]
    assert values["ssim"] == pytest.approx(1.0) and "ssim" not in reasons
    assert depth_error(zero, truth)[0] is None
    assert depth_error(half, np.zeros((8, 8))) == (
        None, "the scene's true depth has no surface in the voxels' view")
    values, reasons = scored(zero, half)
    assert all(v is None or np.isfinite(v) for v in values.values()), values
    errors = SplitErrors.of({"all": {"relative_l2": float("inf"), "nmse_db": float("inf"),
                                   "amplitude_rmse": 1.0,
                                   "relative_amplitude_rmse": float("inf"),
                                   "phase_error": float("nan"), "n_samples": 4},
                           "heldout_pixels": {"relative_l2": None, "nmse_db": None,
                                              "amplitude_rmse": None,
                                              "relative_amplitude_rmse": None,
                                              "phase_error": None, "n_samples": 0},
                           "heldout_frequencies": {"relative_l2": 0.5, "nmse_db": -6.0,
                                                   "amplitude_rmse": 0.1,
                                                   "relative_amplitude_rmse": 0.2,
                                                   "phase_error": 0.1, "n_samples": 4},
                           "heldout_pixels_inside": {"relative_l2": 0.0,
                                                     "nmse_db": -float("inf"),
                                                     "amplitude_rmse": 0.0,
                                                     "relative_amplitude_rmse": 0.0,
                                                     "phase_error": 0.0, "n_samples": 4}})
    assert errors.all.relative_l2 is None and errors.all.amplitude_rmse == 1.0
    assert "true field is zero" in errors.all.null_reasons["phase_error"]
    assert set(errors.heldout_pixels.null_reasons) == {
        "relative_l2", "nmse_db", "amplitude_rmse", "relative_amplitude_rmse", "phase_error"}
    assert errors.heldout_frequencies.null_reasons is None
    assert errors.heldout_pixels_inside.nmse_db is None
    assert "exact" in errors.heldout_pixels_inside.null_reasons["nmse_db"]
    field = fixtures.point_phasor_field()
    still = field.replace(values=np.zeros_like(field.values))
    den = denoising_metrics(still, field, field)
    assert den.gain_db is None and set(den.null_reasons) == {
        "noisy_relative_l2", "relative_l2", "gain_db"}


# ------------------------------------------------------------------ after the last stage
class _FullFile:
    """A file whose writes fail with ENOSPC, as on a full disk."""

    def __init__(self, handle) -> None:
        self.handle = handle

    def write(self, data) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    def __getattr__(self, name):
        return getattr(self.handle, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.handle.close()


def _full_disk_for(monkeypatch, stem: str) -> None:
    """ENOSPC for every write of the file named ``stem`` + its suffix (at its temporary
    path, where atomic writes write it)."""
    real_open = open
    temporary = re.compile(rf"^\.{re.escape(stem)}\.\d+\.[0-9a-f]{{8}}\.tmp")

    def fake(path, mode="r"):
        handle = real_open(path, mode)
        return _FullFile(handle) if temporary.match(Path(path).name) and "w" in mode else handle

    monkeypatch.setattr(files, "open", fake, raising=False)


def test_a_full_disk_at_report_html_of_image_is_recorded_as_failed(workdir, tools,
                                                                     monkeypatch):
    assert tools.run(*IMAGE_ONLY, "stop_after=capture", "hydra.run.dir=src").returncode == 0
    _full_disk_for(monkeypatch, "report")
    run = workdir / "run"
    result = tools.run("image", str(workdir / "src" / "capture.hdf5"), "figures.enabled=false",
                       f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    line = tools.one_error_line(result)
    assert re.fullmatch(r"error: \S+/run/report\.html: no space left on device .*", line), line
    metrics = metrics_of(run)
    assert metrics["status"] == "failed"
    assert metrics["error"] == {"stage": "report", "message": line.removeprefix("error: ")}
    assert inspect_run_dir(run, ()).status not in FINISHED   # a resumed sweep runs it again
    assert not (run / "report.html").exists() and not tools.temporaries(run)
    assert not (run / LOCK_NAME).exists()


def test_a_failure_in_the_console_summary_is_recorded_as_failed(workdir, tools, monkeypatch):
    """The run's last step, the summary table on the console, breaks (a bug): the record
    says failed, not completed."""
    from nlosfw.cli import reporter

    def broken(metrics):
        raise RuntimeError("the summary broke")

    monkeypatch.setattr(reporter, "summary_table", broken)
    run = workdir / "run"
    result = tools.run(*tools.QUICK, f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    line = tools.one_error_line(result)
    assert line.startswith("error: RuntimeError: the summary broke (an unexpected failure")
    assert "Traceback" not in result.stdout
    metrics = metrics_of(run)
    assert metrics["status"] == "failed"
    assert metrics["error"] == {"stage": "report", "message": "RuntimeError: the summary broke"}
    assert (run / "report.html").is_file() and not (run / LOCK_NAME).exists()


def test_a_full_disk_at_metrics_json_leaves_the_run_unfinished(workdir, tools, monkeypatch):
    """Nothing says completed when metrics.json itself cannot be written: the run reads as
    unfinished (a resumed sweep sets it aside and runs it again)."""
    _full_disk_for(monkeypatch, "metrics")
    run = workdir / "run"
    result = tools.run(*tools.QUICK, f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    assert "metrics.json: no space left on device" in tools.one_error_line(result)
    assert not (run / "metrics.json").exists()
    assert inspect_run_dir(run, ()).status is None and not (run / LOCK_NAME).exists()


# ------------------------------------------------------------------ console and exit status
def test_an_unexpected_failure_prints_no_traceback_on_the_console(workdir, tools,
                                                                  monkeypatch):
    """A bug in a stage: one line, the traceback in run.log only (the console's filter
    used to let every error record through, the run log's traceback included)."""
    from nlosfw.pipeline import engine

    def broken(*args, **kwargs):
        raise KeyError("a bug in a stage")

    monkeypatch.setattr(engine, "STAGES", tuple(
        engine.Stage(s.name, broken) if s.name == "reconstruct" else s for s in engine.STAGES))
    run = workdir / "run"
    result = tools.run(*tools.QUICK, f"hydra.run.dir={run}")
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stdout + result.stderr, result.stdout
    assert tools.one_error_line(result).startswith("error: KeyError: 'a bug in a stage'")
    assert "Traceback" in (run / "run.log").read_text()
    assert metrics_of(run)["error"]["stage"] == "reconstruct"


def test_a_sweep_subdir_that_cannot_be_written_is_exit_status_2(workdir, tools,
                                                                 read_only_dir):
    """The jobs' folders (hydra.sweep.subdir) lie in a read-only place the preflight does
    not resolve: still a one-line refusal with exit status 2, as the README promises."""
    result = tools.run("-m", *tools.QUICK, "simulator.seed=0,1",
                       f"hydra.sweep.dir={workdir / 'sweep'}",
                       "hydra.sweep.subdir=../read-only/${hydra.job.num}")
    assert result.returncode == 2, result.stderr
    line = tools.one_error_line(result)
    assert re.fullmatch(r"error: hydra\.sweep\.dir: \S+ cannot be written \((read-only file "
                        r"system|permission denied)\); choose another output directory", line), line
    assert list(read_only_dir.iterdir()) == []


def test_a_hydra_output_subdir_that_cannot_be_written_is_exit_status_2(workdir, tools,
                                                                        read_only_dir):
    result = tools.run(*tools.QUICK, "hydra.run.dir=run",
                       f"hydra.output_subdir={read_only_dir / 'hydra'}")
    assert result.returncode == 2, result.stderr
    assert re.fullmatch(rf"error: hydra\.run\.dir: {read_only_dir} cannot be written "
                        r"\((read-only file system|permission denied)\); choose another "
                        r"output directory", tools.one_error_line(result))

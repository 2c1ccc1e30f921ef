"""A failed sweep job never stops or kills the others: each job ends with its own status in
its own metrics.json, the sweep runs every job, and exits non-zero at the end with one line
naming the failed ones (with Hydra's basic launcher and with the parallel one)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nlosfw.pipeline.lifecycle import LOCK_NAME

#: Swept over the tiny scene's patch: an albedo of 0 leaves interp nothing to fit (a
#: one-line error at run time, in the fit stage, exit status 2); the others complete.
ALBEDOS = "scene.geometry.0.albedo=1,0,0.5"
FIT_FAILS = "error: interp: the field's values are all zero; nothing to fit"


def statuses(sweep: Path, jobs: int) -> list[str]:
    """Each job's status, from its own metrics.json."""
    return [json.loads((sweep / str(n) / "metrics.json").read_text())["status"]
            for n in range(jobs)]


def assert_clean(sweep: Path, tools) -> None:
    assert list(sweep.rglob(LOCK_NAME)) == [] and not tools.temporaries(sweep)


def test_a_failed_job_does_not_stop_a_sequential_sweep(workdir, tools):
    sweep = workdir / "sweep"
    result = tools.run("-m", *tools.QUICK, ALBEDOS, f"hydra.sweep.dir={sweep}")
    assert result.returncode == 2, result.stderr
    assert tools.one_error_line(result) == (
        f"error: job 1 of 3 of the sweep failed ({ALBEDOS.split('=')[0]}=0): "
        f"{FIT_FAILS.removeprefix('error: ')}")
    assert statuses(sweep, 3) == ["completed", "failed", "completed"]
    failed = json.loads((sweep / "1" / "metrics.json").read_text())
    assert failed["error"] == {"stage": "fit", "message": FIT_FAILS.removeprefix("error: ")}
    assert_clean(sweep, tools)


def test_a_failed_job_does_not_kill_its_siblings_in_a_parallel_sweep(workdir, tools):
    """The joblib launcher (two workers): the failing job's exception used to make joblib
    kill the other worker mid-stage, and the third job never started."""
    sweep = workdir / "sweep"
    result = tools.nlosfw("-m", "hydra/launcher=parallel", *tools.QUICK,
                          "scene.geometry.0.albedo=0,1,0.5", f"hydra.sweep.dir={sweep}",
                          cwd=workdir)
    assert result.returncode == 2, result.stderr
    assert tools.one_error_line(result).startswith(
        "error: job 0 of 3 of the sweep failed (scene.geometry.0.albedo=0): interp: ")
    assert statuses(sweep, 3) == ["failed", "completed", "completed"]
    assert_clean(sweep, tools)


def test_every_failed_job_is_named_and_an_unexpected_one_sets_the_status(workdir, tools,
                                                                         monkeypatch):
    """Two failures of their own kinds, a refusal (exit status 2) and a bug (1), around a
    job that completes: every job runs, the one line names both, the status is 1."""
    from nlosfw.pipeline import engine

    def transform(context, done):
        albedo = context.plan.config["scene"]["geometry"][0]["albedo"]
        if albedo == 0.5:
            raise TypeError("a bug for this albedo only")
        return original(context, done)

    (original,) = [s.run for s in engine.STAGES if s.name == "transform"]
    monkeypatch.setattr(engine, "STAGES", tuple(
        engine.Stage(s.name, transform) if s.name == "transform" else s
        for s in engine.STAGES))
    sweep = workdir / "sweep"
    result = tools.run("-m", *tools.QUICK, "scene.geometry.0.albedo=0,0.5,1",
                       f"hydra.sweep.dir={sweep}")
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    assert tools.one_error_line(result) == (
        "error: 2 of 3 jobs of the sweep failed: job 0 (scene.geometry.0.albedo=0), job 1 "
        "(scene.geometry.0.albedo=0.5); each job's metrics.json and run.log say why")
    assert statuses(sweep, 3) == ["failed", "failed", "completed"]
    bug = json.loads((sweep / "1" / "metrics.json").read_text())["error"]
    assert bug == {"stage": "transform", "message": "TypeError: a bug for this albedo only"}
    lines = [line for line in result.stderr.splitlines() if line.startswith("job ")]
    assert lines == ["job 0 failed: interp: the field's values are all zero; nothing to fit",
                     "job 1 failed: TypeError: a bug for this albedo only (an unexpected failure "
                     "in stage transform; the traceback is in run.log, or on the console with "
                     "--debug)"]
    assert_clean(sweep, tools)


def test_a_resumed_sweep_runs_its_failed_jobs_again_and_skips_the_others(workdir, tools):
    sweep = workdir / "sweep"
    args = ("-m", *tools.QUICK, ALBEDOS, f"hydra.sweep.dir={sweep}")
    assert tools.run(*args).returncode == 2
    first = {n: (sweep / str(n) / "metrics.json").stat().st_mtime_ns for n in range(3)}
    result = tools.run(*args)
    assert result.returncode == 2, result.stderr
    assert statuses(sweep, 3) == ["completed", "failed", "completed"]
    assert (sweep / "0" / "metrics.json").stat().st_mtime_ns == first[0]     # skipped
    assert (sweep / "1" / "metrics.json").stat().st_mtime_ns != first[1]     # run again
    assert len(list((sweep / "1").glob("interrupted-*"))) == 1              # set aside


@pytest.mark.parametrize("launcher", ["basic", "parallel"])
def test_a_sweep_without_failures_still_exits_0(workdir, tools, launcher):
    sweep = workdir / "sweep"
    extra = ("hydra/launcher=parallel",) if launcher == "parallel" else ()
    result = tools.nlosfw("-m", *extra, *tools.QUICK, "simulator.seed=0,1",
                          f"hydra.sweep.dir={sweep}", cwd=workdir)
    assert result.returncode == 0, result.stderr
    assert statuses(sweep, 2) == ["completed", "completed"]
    assert "error" not in result.stderr

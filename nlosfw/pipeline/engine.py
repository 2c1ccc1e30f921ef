"""The run engine: a plan's stages in order, reported through the run hooks.

The fields imaged side by side, all with the same imager on the same voxels: the true
full-resolution field (the reference), the raw samples the models train on (a sub-grid,
or scattered points), the ``interp`` baseline's prediction, and the prediction of every
field model of the run (``model`` and each ``compare`` label); every reconstruction is
scored against the one from the true field.

:class:`Pipeline` runs the table :data:`STAGES` up to ``stop_after`` (the stages that
apply to the plan: ``model=none`` images the capture alone, without fit and predict; a
stopped run still draws the figures of what it computed). It draws and prints
nothing: every step is a hook call (:class:`~nlosfw.pipeline.events.RunEvents`), the
metrics are recorded by a subscriber to those hooks
(:class:`~nlosfw.pipeline.recorder.MetricsRecorder`), the report files by the report
plugin's, the console by the command line's.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal

from nlosfw.common import yaml_safe
from nlosfw.common.errors import NlosfwError, one_line
from nlosfw.common.logs import FILE_ONLY, to_file
from nlosfw.common.version import __version__
from nlosfw.pipeline import lifecycle
from nlosfw.pipeline.budget import memory_summary
from nlosfw.pipeline.cache import Cache
from nlosfw.pipeline.capture_stage import capture_stage
from nlosfw.pipeline.context import Stage, StageContext, StageFunction, always, fits_models
from nlosfw.pipeline.events import RunEvents
from nlosfw.pipeline.field_stages import fit_stage, predict_stage, transform_stage
from nlosfw.pipeline.files import PLANNED_NAMES, RunFiles
from nlosfw.pipeline.image_stage import reconstruct_stage, report_stage
from nlosfw.pipeline.interrupts import as_interruption, signals_raise
from nlosfw.pipeline.metrics import RunError, RunInfo, RunMetrics, Status
from nlosfw.pipeline.pause import pause_point
from nlosfw.pipeline.plan import RunPlan
from nlosfw.pipeline.recorder import MetricsRecorder
from nlosfw.pipeline.results import StageResults
from nlosfw.pipeline.settings import STAGES as STAGE_NAMES
from nlosfw.plugins import PluginHost

log = logging.getLogger(__name__)

#: What each stage runs, and whether a plan performs it (``model=none``: no fit, no predict).
_STAGE_FUNCTIONS: dict[str, tuple[StageFunction, Callable[[RunPlan], bool]]] = {
    "capture": (capture_stage, always),
    "transform": (transform_stage, always),
    "fit": (fit_stage, fits_models),
    "predict": (predict_stage, fits_models),
    "reconstruct": (reconstruct_stage, always),
    "report": (report_stage, always),
}

#: The stages of a run, in the order :data:`nlosfw.pipeline.settings.STAGES` names them.
STAGES: tuple[Stage, ...] = tuple(Stage(name, *_STAGE_FUNCTIONS[name]) for name in STAGE_NAMES)


class Pipeline:
    """One run of a plan's stages up to ``stop_after``, writing into ``run_dir``.

    ``resume``: the run is a job of a sweep that may be resumed in its directory (a
    finished job of the same configuration is then skipped).
    """

    def __init__(self, plan: RunPlan, run_dir: Path, host: PluginHost,
                 resume: bool = False) -> None:
        self.plan = plan
        self.run_dir = Path(run_dir)
        self.host = host
        self.resume = resume
        self.events = RunEvents(host.manager)
        self.files = RunFiles(self.run_dir, self.events,
                              keep=frozenset(plan.settings.output.keep))
        self.recorder = MetricsRecorder(run_info(plan, self.run_dir))
        self.stage_results = StageResults()
        """What the stages produced so far (all of it once :meth:`run` has returned)."""
        self.stage_reached: str | None = None
        """The stage running now, or the last one started."""
        self._ended = False

    @property
    def metrics(self) -> RunMetrics:
        """The run's metrics so far (all of them once :meth:`run` has returned)."""
        return self.recorder.metrics

    def run(self) -> float | None:
        """Run the stages; returns the held-out NMSE (dB) of the model, None when stopped
        early or skipped. Everything that can be checked is checked before the first byte
        is written; a failed or interrupted (SIGINT, SIGTERM) run leaves metrics.json
        saying where and why, and no temporary file."""
        settings = self.plan.settings
        to_file(self.plan.read_log)         # said while the plan read the capture file
        log.info("%s", memory_summary(self.plan.memory))
        with signals_raise(), lifecycle.held(
                self.run_dir, self.plan.config, settings, PLANNED_NAMES,
                resume=self.resume) as hold:
            if hold is None:
                log.info("skipping: %s already holds a finished run of this configuration",
                         self.run_dir)
                return None
            self.files.hold = hold
            self.host.manager.register(self.recorder)
            try:
                return self._run_held()
            finally:
                self.host.manager.unregister(self.recorder)

    def _run_held(self) -> float | None:
        started = time.perf_counter()
        shown = dict(self.plan.used_config())
        try:
            self.events.run_start(str(self.run_dir), shown)
            self.files.write_text("config", yaml_safe.dump(shown))
            self._stages()
            metrics = self._finish(shown, started)
        except BaseException as err:  # any failure, ours or a bug: record it, then re-raise
            self._record_end(err, time.perf_counter() - started)
            raise
        return objective(metrics)

    def _finish(self, shown: dict[str, object], started: float) -> RunMetrics:
        """After the last stage, as part of the report: report.html, then metrics.json
        saying completed (or stopped) once everything before it is written, then
        ``on_run_end`` (the console's summary). A failure in any of them is the run's:
        :meth:`_record_end` records it, replacing that metrics.json."""
        settings = self.plan.settings
        status: Literal["completed", "stopped"] = (
            "completed" if settings.stop_after is None else "stopped")
        metrics = self.recorder.finish(
            status, time.perf_counter() - started,
            stopped_after=None if status == "completed" else settings.last_stage)
        self.stage_reached = "report"
        self.events.write_page(self.files, metrics, shown)
        self.files.write_metrics(metrics)
        self._ended = True
        self.events.run_end(str(self.run_dir), metrics, status)
        return metrics

    def _stages(self) -> None:
        context = StageContext(
            plan=self.plan, files=self.files, events=self.events, recorder=self.recorder,
            cache=Cache(self.plan.settings.cache.dir, self.plan.settings.cache.enabled,
                        max_gb=self.plan.settings.cache.max_gb))
        for stage in STAGES:
            if not self._performs(stage):
                continue
            self.stage_reached = stage.name
            start = time.perf_counter()
            self.events.stage_start(stage.name)
            log.info("stage %s: started", stage.name, extra=FILE_ONLY)
            pause_point(stage.name)           # tests only: NLOSFW_TEST_PAUSE holds the run
            result = stage.run(context, self.stage_results)
            if result is not None:
                self.stage_results = self.stage_results.with_result(result)
                self.events.stage_result(stage.name, result)
            seconds = time.perf_counter() - start
            log.info("stage %s: %.2f s", stage.name, seconds, extra=FILE_ONLY)
            self.events.stage_end(stage.name, seconds)

    def _performs(self, stage: Stage) -> bool:
        """Whether the run performs ``stage``: the plan has it and ``stop_after`` reaches it;
        a stopped run still draws the figures of what it computed (after ``reconstruct``
        its images, before it the capture's time profile)."""
        if not stage.applies(self.plan):
            return False
        if self.plan.settings.runs(stage.name):
            return True
        return stage.name == "report" and self.stage_results.capture is not None

    def _record_end(self, err: BaseException, seconds: float) -> None:
        """metrics.json with status failed or interrupted, the stage and the one-line reason
        (replacing one the run wrote before it failed; only what ran, the error and the
        timings when the sections cannot be written), and the on_run_end hook unless it
        was the hook that failed, never masking the error."""
        interruption = as_interruption(err)
        status: Status = "failed" if interruption is None else "interrupted"
        if interruption is not None:
            error = RunError(stage=self.stage_reached, message=str(interruption),
                             signal=interruption.signal_name)
        else:
            message = (one_line(err, whole=True) if isinstance(err, NlosfwError)
                       else f"{type(err).__name__}: {one_line(err, whole=True)}")
            error = RunError(stage=self.stage_reached, message=message)
        try:
            metrics = self.recorder.finish(status, seconds, error)
            try:
                self.files.write_metrics(metrics, replace=True)
            except TypeError as unwritable:   # a value its type does not admit: a bug
                log.error("metrics.json: its sections cannot be written (%s); it holds the "
                          "error and the timings only", one_line(unwritable))
                metrics = self.recorder.bare(error)
                self.files.write_metrics(metrics, replace=True)
            if not self._ended:
                self._ended = True
                self.events.run_end(str(self.run_dir), metrics, status)
        except Exception as failure:  # the original failure is what the user must see
            log.error("could not record the %s run in %s: %s", status, self.run_dir,
                      one_line(failure))


def objective(metrics: RunMetrics) -> float | None:
    """The held-out pixels' NMSE (dB) of the model (else of interp), against half B's
    measured field with count splitting: what a sweep minimises."""
    entry = metrics.field_entry("model") or metrics.field_entry("interp")
    if entry is None or entry.splits is None:
        return None
    if entry.splits.heldout_measurement is not None:
        return entry.splits.heldout_measurement.nmse_db
    return entry.splits.heldout_pixels.nmse_db


def run_info(plan: RunPlan, run_dir: Path) -> RunInfo:
    """The run's plugins and capture: a scene and its simulator, or a file and its format
    (known once the capture stage has read it, unless ``capture.format`` forces it)."""
    source = plan.settings.capture
    path = None if source.path is None else Path(source.path).expanduser().resolve()
    from_file = path is not None
    return RunInfo(dir=str(run_dir), nlosfw_version=__version__,
                   started=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                   config_hash=lifecycle.config_hash(plan.config),
                   scene=plan.selected("scene"), simulator=plan.selected("simulator"),
                   capture_file=None if path is None else str(path),
                   capture_format=source.format if from_file else None,
                   transform=plan.selected("transform"), model=plan.selected("model"),
                   imager=plan.selected("imager"))

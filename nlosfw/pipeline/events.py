"""What a run reports, and to whom: typed calls of the run hooks.

The engine and its stages report through :class:`RunEvents`; every report is a call of
a hook of :mod:`nlosfw.plugins.hookspecs` on the run's plugin manager, so nlosfw's own
subscribers (the metrics recorder, the command line's console reporter, the report
plugin) and third-party plugins all see the same events. Nothing here draws or prints.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from nlosfw.pipeline.files import RunFiles
    from nlosfw.pipeline.metrics import RunMetrics
    from nlosfw.pipeline.results import CaptureResult, RunResults
    from nlosfw.pipeline.settings import RunSettings

#: ``on_progress(done, total)``, as imagers and simulators take it.
ProgressCallback = Callable[[int, int], None]


class RunEvents:
    """The run hooks of one plugin manager, as typed methods."""

    def __init__(self, manager: pluggy.PluginManager) -> None:
        self._hook = manager.hook

    def run_start(self, run_dir: str, config: dict[str, object]) -> None:
        self._hook.on_run_start(run_dir=run_dir, config=config)

    def run_end(self, run_dir: str, metrics: RunMetrics, status: str) -> None:
        self._hook.on_run_end(run_dir=run_dir, metrics=metrics.to_json(), status=status)

    def stage_start(self, stage: str) -> None:
        self._hook.on_stage_start(stage=stage)

    def stage_end(self, stage: str, seconds: float) -> None:
        self._hook.on_stage_end(stage=stage, seconds=seconds)

    def stage_result(self, stage: str, result: object) -> None:
        self._hook.on_stage_result(stage=stage, result=result)

    def progress(self, task: str, done: int, total: int | None = None, info: str = "") -> None:
        """Task ``task`` of the current stage has done ``done`` of ``total`` steps."""
        self._hook.on_progress(task=task, done=done, total=total, info=info)

    def progress_callback(self, task: str) -> ProgressCallback:
        """``on_progress(done, total)`` reporting task ``task``."""
        return lambda done, total: self.progress(task, done, total)

    def training_step(self, source: str, model: str, step: int, total_steps: int,
                      loss: float, val_loss: float | None) -> None:
        self._hook.on_training_step(source=source, model=model, step=step,
                                    total_steps=total_steps, loss=loss, val_loss=val_loss)

    def artefact_written(self, path: str, kind: str) -> None:
        self._hook.on_artefact_written(path=path, kind=kind)

    def write_report(self, files: RunFiles, results: RunResults, metrics: RunMetrics,
                     settings: RunSettings) -> None:
        self._hook.write_run_report(files=files, results=results, metrics=metrics,
                                    settings=settings)

    def write_capture_report(self, files: RunFiles, capture: CaptureResult,
                             depth_range: tuple[float, float], metrics: RunMetrics,
                             settings: RunSettings) -> None:
        self._hook.write_capture_report(files=files, capture=capture, depth_range=depth_range,
                                        metrics=metrics, settings=settings)

    def write_page(self, files: RunFiles, metrics: RunMetrics,
                   config: dict[str, object]) -> None:
        self._hook.write_run_page(files=files, metrics=metrics, config=config)

"""The console of a run: an ordinary subscriber to the run hooks.

:class:`ConsoleReporter` draws what the engine reports (as pytest's terminal reporter is
a plugin of pytest's own hooks): before the run its choices, changed options and plan;
a progress line or bar per task of each stage (simulation, phasor field, each model's
training, prediction, each reconstruction, figures); at the end the summary table and
the size of the run directory. The command line registers it; :func:`nlosfw.run` does
not, so a notebook gets no console output.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.progress import Progress, TaskID

from nlosfw.cli.console import app_console, progress_bar
from nlosfw.cli.overview import overview_lines
from nlosfw.cli.summary import summary_table
from nlosfw.common.files import format_bytes
from nlosfw.common.text import console_text as escape
from nlosfw.pipeline import Artefact, RunMetrics, RunPlan
from nlosfw.plugins import PluginHost, hookimpl


class ConsoleReporter:
    """Draws one run on a rich console."""

    def __init__(self, host: PluginHost, plan: RunPlan, console: Console | None = None) -> None:
        self.host = host
        self.settings = plan.settings
        self.choices = plan.choices
        self.console = console or app_console()
        self._progress: Progress | None = None
        self._tasks: dict[str, TaskID] = {}

    @hookimpl
    def on_run_start(self, run_dir: str, config: dict[str, object]) -> None:
        self.console.print(f"[bold]nlosfw run[/] → {escape(run_dir)}", highlight=False)
        for line in overview_lines(config, self.host, self.settings, self.choices):
            self.console.print(line, highlight=False)
        self.console.print("  full configuration: config.yaml and .hydra/ in the run "
                           "directory", highlight=False)

    @hookimpl
    def on_stage_start(self, stage: str) -> None:
        self._stop()
        self._progress = progress_bar(self.console)
        self._progress.start()
        if stage == "report" and self.settings.figures.enabled:
            self._update("figures", 0, None, "")

    @hookimpl
    def on_progress(self, task: str, done: int, total: int | None, info: str) -> None:
        self._update(task, done, total, info)

    @hookimpl
    def on_training_step(self, source: str, model: str, step: int, total_steps: int,
                         loss: float, val_loss: float | None) -> None:
        val = "" if val_loss is None else f" val {val_loss:.3g}"
        self._update(f"fit {model}", step, total_steps, f"loss {loss:.3g}{val}")

    @hookimpl
    def on_artefact_written(self, path: str, kind: str) -> None:
        if kind == "figure":
            self._update("figures", 0, None, Path(path).name)

    @hookimpl
    def on_stage_end(self, stage: str, seconds: float) -> None:
        if self._progress is not None:
            for task in self._progress.tasks:  # a spinner becomes a completed line
                if task.total is None:
                    self._progress.update(task.id, total=1, completed=1)
        self._stop()

    @hookimpl
    def on_run_end(self, run_dir: str, metrics: dict[str, object], status: str) -> None:
        self._stop()
        if status not in ("completed", "stopped"):
            return  # the command line prints the error in one line
        run = RunMetrics.from_json(metrics)
        self.console.print(summary_table(run))
        size = sum(p.stat().st_size for p in Path(run_dir).rglob("*") if p.is_file())
        if status == "stopped" and run.run.stopped_after:
            status = f"stopped after {run.run.stopped_after}"
        self.console.print(f"[bold green]done[/] ({escape(status)}): {escape(run_dir)}, "
                           f"{format_bytes(size)} {escape(self._kept_text())}",
                           highlight=False)

    def _update(self, task: str, done: int, total: int | None, info: str) -> None:
        if self._progress is None:
            return
        if task not in self._tasks:
            self._tasks[task] = self._progress.add_task(escape(task), total=total, info="")
        self._progress.update(self._tasks[task], completed=done, total=total,
                              info=escape(info))

    def _stop(self) -> None:
        if self._progress is not None:
            self._progress.stop()
        self._progress = None
        self._tasks = {}

    def _kept_text(self) -> str:
        """Which large files the run kept and which output.keep left out."""
        keep = self.settings.output.keep
        kept = ", ".join(str(a) for a in keep) or "none"
        left = ", ".join(str(a) for a in Artefact if a not in keep)
        return (f"(large files kept: {kept}" + (f"; not written: {left}, see output.keep)"
                                                 if left else ")"))

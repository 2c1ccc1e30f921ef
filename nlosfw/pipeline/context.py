"""What every stage of a run works with, and the rows of the table of stages the engine runs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from nlosfw.pipeline.cache import Cache
from nlosfw.pipeline.events import RunEvents
from nlosfw.pipeline.files import RunFiles
from nlosfw.pipeline.plan import RunPlan
from nlosfw.pipeline.recorder import MetricsRecorder
from nlosfw.pipeline.results import StageResults


@dataclass(frozen=True, eq=False)
class StageContext:
    """The plan, the run's files, the cache and the events of one run."""

    plan: RunPlan
    files: RunFiles
    cache: Cache
    events: RunEvents
    recorder: MetricsRecorder
    """The run's metrics so far (the report stage draws from them)."""


def always(plan: RunPlan) -> bool:
    """A stage every run performs (up to ``stop_after``)."""
    return True


def fits_models(plan: RunPlan) -> bool:
    """A stage of the runs that fit field models (not ``model=none``)."""
    return not plan.images_only


#: A stage: it reads the results so far and returns its own (None: nothing to keep).
StageFunction = Callable[[StageContext, StageResults], object]


@dataclass(frozen=True)
class Stage:
    """One row of the engine's table: a stage's name and the function that runs it (its
    result, if any, joins :class:`~nlosfw.pipeline.results.StageResults`)."""

    name: str
    run: StageFunction
    applies: Callable[[RunPlan], bool] = always
    """Whether the plan performs this stage at all (``model=none`` skips fit and predict)."""

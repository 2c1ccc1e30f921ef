"""Hook specifications of nlosfw (the ``nlosfw`` pluggy project).

A plugin is a module named by an entry point in the ``nlosfw`` group whose
functions are marked with :data:`hookimpl` and named after these specs. The
``register_*`` hooks receive a ``register`` callable (see
:class:`nlosfw.plugins.registry.Registrar`) instead of returning values, so new
keyword arguments can be added to it without breaking existing plugins.
Plugins may implement any subset of the hooks, and may omit arguments.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:  # the run's types, for the run hooks' annotations only
    from nlosfw.pipeline.files import RunFiles
    from nlosfw.pipeline.metrics import RunMetrics
    from nlosfw.pipeline.results import CaptureResult, RunResults
    from nlosfw.pipeline.settings import RunSettings
    from nlosfw.plugins.array_backends import ArrayBackendRegistrar
    from nlosfw.plugins.networks import NetworkRegistrar
    from nlosfw.plugins.registry import Registrar

PROJECT = "nlosfw"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


# ------------------------------------------------------------------ registration
@hookspec
def register_simulators(register: Registrar) -> None:
    """Register :class:`~nlosfw.simulate.Simulator` plugins: ``register(name, factory, ...)``."""


@hookspec
def register_phasor_transforms(register: Registrar) -> None:
    """Register :class:`~nlosfw.transform.PhasorTransform` plugins."""


@hookspec
def register_field_models(register: Registrar) -> None:
    """Register :class:`~nlosfw.model.FieldModel` plugins."""


@hookspec
def register_networks(register: NetworkRegistrar) -> None:
    """Register networks for the shared neural trainer (see :mod:`nlosfw.plugins.networks`).

    ``register(name, backend="torch" | "jax", factory="module:function",
    config="module:Config", description=..., test_config=..., requires=..., presets=...)``;
    each becomes the field-model plugin ``<name>_<backend>`` (``engine=``, ``backend``'s
    old name, is deprecated).
    """


@hookspec
def register_imagers(register: Registrar) -> None:
    """Register :class:`~nlosfw.image.Imager` plugins."""


@hookspec
def register_array_backends(register: ArrayBackendRegistrar) -> None:
    """Register array backends of the FFT-based imagers' ``device`` option (see
    :mod:`nlosfw.plugins.array_backends`): ``register(name, factory="module:Class",
    counter="module:function", devices=["cuda"])``."""


@hookspec
def register_capture_formats(register: Registrar) -> None:
    """Register :class:`~nlosfw.capture.CaptureFormat` plugins (readers and writers of capture
    files; capabilities ``readable``, ``writable``)."""


# ------------------------------------------------------------------ run lifecycle
# A run reports everything it does through these hooks; its metrics, the console's
# progress and the report files are written by subscribers to them (nlosfw's own
# metrics recorder, the command line's console reporter, the report plugin
# ``nlosfw.report.hooks``), so a third-party plugin sees exactly what they see.
@hookspec
def on_run_start(run_dir: str, config: dict[str, object]) -> None:
    """A run begins; ``config`` is the resolved configuration as plain data."""


@hookspec
def on_run_end(run_dir: str, metrics: dict[str, object], status: str) -> None:
    """A run ends; ``status`` is ``completed``, ``stopped`` (``stop_after``) or ``failed``.

    ``metrics`` is what metrics.json holds.
    """


@hookspec
def on_stage_start(stage: str) -> None:
    """A pipeline stage begins: capture, transform, fit, predict, reconstruct or report."""


@hookspec
def on_stage_end(stage: str, seconds: float) -> None:
    """A pipeline stage has finished: capture, transform, fit, predict, reconstruct or report."""


@hookspec
def on_stage_result(stage: str, result: object) -> None:
    """What a stage produced, typed (:mod:`nlosfw.pipeline.results`): ``capture`` a
    ``CaptureResult``, ``transform`` a ``TransformResult``, ``fit`` a ``FitResult``,
    ``predict`` an ``ImagedFields``, ``reconstruct`` a ``Reconstructions``."""


@hookspec
def on_progress(task: str, done: int, total: int | None, info: str) -> None:
    """Progress of one task of the current stage (``simulate letter_t (analytic)``,
    ``image model``, ...): ``done`` of ``total`` steps (``None``: not counted), and a
    short ``info`` text. A task is finished when ``done == total``."""


@hookspec
def on_training_step(source: str, model: str, step: int, total_steps: int, loss: float,
                     val_loss: float | None) -> None:
    """A field model reports training progress.

    ``source`` is its role in the run (``model``, ``interp`` or a ``compare`` label),
    ``model`` its plugin name.
    """


@hookspec
def on_artefact_written(path: str, kind: str) -> None:
    """A file was written into the run directory; ``kind`` is e.g. ``capture`` or ``figure``."""


# ------------------------------------------------------------------ reports
@hookspec
def write_run_report(files: RunFiles, results: RunResults, metrics: RunMetrics,
                     settings: RunSettings) -> None:
    """The report stage of a complete run: write figures and tables into the run directory
    through ``files`` (which claims and writes each file atomically)."""


@hookspec
def write_capture_report(files: RunFiles, capture: CaptureResult,
                         depth_range: tuple[float, float], metrics: RunMetrics,
                         settings: RunSettings) -> None:
    """The report stage of a run stopped before it imaged (``stop_after`` capture,
    transform, fit or predict): figures of the ``capture`` it read or simulated (nlosfw's:
    its time profile with the planes' ``depth_range`` (m) shaded), through ``files``."""


@hookspec
def write_run_page(files: RunFiles, metrics: RunMetrics, config: dict[str, object]) -> None:
    """After ``metrics.json``: write the run's page (``report.html``) through ``files``."""

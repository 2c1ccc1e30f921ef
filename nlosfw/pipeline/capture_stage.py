"""The capture stage: read ``capture.path`` or simulate the scene (cached), preprocess it,
split its counts in two (``split.count_splitting``), write ``capture.hdf5`` (half A when
split).

A noisy scene's transport is rendered once: the noise-free capture is cached under its
own key, the noisy one is that capture with noise added (cached too), and the
noise-free one is kept for the denoising metrics.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.capture.source import prepare
from nlosfw.common.config import config_to_dict
from nlosfw.common.hashing import cache_key, file_digest
from nlosfw.evaluation.count_splitting import split_counts
from nlosfw.pipeline.context import StageContext
from nlosfw.pipeline.measure import capture_metrics
from nlosfw.pipeline.results import CaptureResult, StageResults
from nlosfw.pipeline.settings import Artefact
from nlosfw.simulate.geometry import resolve_mesh_paths
from nlosfw.simulate.interface import Simulator
from nlosfw.simulate.scene import NoiseConfig, Scene


def capture_stage(run: StageContext, done: StageResults) -> CaptureResult:
    """The run's capture, preprocessed, written as ``capture.hdf5`` (``output.keep``)."""
    if run.plan.settings.capture.path is not None:
        result = _file_capture(run)
    else:
        result = _preprocessed(run, _simulated_capture(run))
    if run.plan.settings.split.count_splitting:
        result = count_split(result, run.plan.settings.split.count_splitting_seed)
    run.files.write("capture", lambda p: write_capture(
        p, result.capture, compression=run.plan.settings.output.compression),
        keep_as=Artefact.capture)
    return dataclasses.replace(result, metrics=capture_metrics(result))


def _file_capture(run: StageContext) -> CaptureResult:
    """The capture of ``capture.path`` as the plan read and preprocessed it; the run is
    labelled with its format."""
    loaded = run.plan.capture
    if loaded is None:  # make_plan reads the file of every plan with capture.path
        raise ValueError("a capture file's run needs the plan's capture")
    versions = run.plan.format_versions or {}
    key = loaded.cache_key(versions.get(loaded.format, "unknown"))
    return CaptureResult(capture=loaded.prepared.capture, key=key, source="file",
                         label=f"{loaded.path.name} ({loaded.format} format)",
                         path=loaded.path.resolve(), format=loaded.format,
                         steps=loaded.prepared.steps)


def _simulated_capture(run: StageContext) -> CaptureResult:
    """The scene's capture (cached), rendering the transport once even for noisy scenes."""
    plan = run.plan
    if plan.simulator is None or plan.scene is None:  # make_plan sets both without a file
        raise ValueError("a simulated capture needs the plan's simulator and scene")
    simulator, scene = plan.simulator.plugin, plan.scene
    clean_scene = dataclasses.replace(scene, noise=NoiseConfig())
    clean_key = simulation_key(plan.simulator.name, plan.simulator.version, simulator,
                             clean_scene)
    label = f"{scene.name} ({plan.simulator.name})"
    task = f"simulate {label}"
    run.events.progress(task, 0)
    clean, hit = _cached(run, clean_key, lambda: simulator.simulate_clean(clean_scene))
    if scene.noise == NoiseConfig():
        run.events.progress(task, 1, 1, "(cached)" if hit else "")
        return CaptureResult(capture=clean, key=clean_key, source="simulated", label=label,
                             simulator=plan.simulator.name, cache_hit=hit)
    key = simulation_key(plan.simulator.name, plan.simulator.version, simulator, scene)
    capture, hit = _cached(run, key, lambda: simulator.add_noise(clean, scene))
    run.events.progress(task, 1, 1, "(cached)" if hit else "")
    return CaptureResult(capture=capture, key=key, source="simulated", label=label,
                         simulator=plan.simulator.name, cache_hit=hit, clean=clean,
                         clean_key=clean_key)


def _preprocessed(run: StageContext, raw: CaptureResult) -> CaptureResult:
    """A simulated capture (and its noise-free twin) with the run's preprocessing."""
    options = run.plan.settings.capture.options
    prepared = prepare(raw.capture, options, frozenset(), run.plan.formats)
    if not prepared.steps:
        return raw
    key = cache_key({"capture": raw.key, **prepared.key_material})
    clean, clean_key = raw.clean, raw.clean_key
    if clean is not None:  # noise-free: no counts, no pile-up to correct
        ideal = dataclasses.replace(options, pileup_pulses=None)
        clean = prepare(clean, ideal, frozenset(), run.plan.formats).capture
        clean_key = cache_key({"capture": raw.clean_key, **prepared.key_material})
    return dataclasses.replace(raw, capture=prepared.capture, key=key, steps=prepared.steps,
                               clean=clean, clean_key=clean_key)


def count_split(result: CaptureResult, seed: int) -> CaptureResult:
    """Count splitting of the run's capture: half A becomes the capture (the models train
    on it), half B the one every score uses; the noise-free capture, if any, is halved to
    A's exposure. A ConfigError for ``split.count_splitting`` when the capture is not
    counts."""
    halves = split_counts(result.capture, seed, where=result.label)
    key = cache_key({"capture": result.key, "count_splitting": int(seed), "half": "A"})
    score_key = cache_key({"capture": result.key, "count_splitting": int(seed), "half": "B"})
    clean, clean_key = result.clean, result.clean_key
    if clean is not None and clean_key is not None:
        clean = clean.replace(H=np.asarray(clean.H) * np.asarray(0.5, dtype=clean.H.dtype))
        clean_key = cache_key({"capture": clean_key, "scaled": 0.5})
    return dataclasses.replace(result, capture=halves.a, key=key, count_split=halves,
                               score_key=score_key, clean=clean, clean_key=clean_key)


def _cached(run: StageContext, key: str,
            compute: Callable[[], Capture]) -> tuple[Capture, bool]:
    return run.cache.get_or_compute(
        "captures", key, compute, lambda p, c: write_capture(p, c, compression=1),
        read_capture)


def simulation_key(name: str, version: str, simulator: Simulator, scene: Scene) -> str:
    """Cache key of a simulated capture: the plugin and its version, its validated
    options, the validated scene with absolute mesh paths, and the mesh files' bytes."""
    scene = resolve_mesh_paths(scene)
    meshes = {item.path: file_digest(Path(item.path)) for item in scene.geometry
              if item.type == "mesh" and item.path}
    return cache_key({"simulator": name, "plugin": version,
                      "options": config_to_dict(simulator.config),
                      "scene": config_to_dict(scene), "meshes": meshes})

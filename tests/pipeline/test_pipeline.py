"""The pipeline in-process: lifecycle hooks, failure records, the cache, single renders."""

import json
import types
from pathlib import Path

import numpy as np
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.image.fft import FFTImager, FFTImagerConfig
from nlosfw.model.interp import InterpConfig, InterpFieldModel
from nlosfw.pipeline import Pipeline, make_plan
from nlosfw.pipeline.cache import Cache
from nlosfw.pipeline.lifecycle import MARKER_NAME
from nlosfw.plugins import hookimpl, load_plugins
from nlosfw.simulate.analytic import AnalyticConfig, AnalyticSimulator
from nlosfw.testing import fixtures

TINY = ["scene=tiny", "model=interp", "figures.enabled=false", "transform.n_frequencies=21",
        "reconstruction.n_depths=4"]


class Tracker:
    """A tracking plugin: records every lifecycle hook call."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict]] = []

    @hookimpl
    def on_run_start(self, run_dir, config):
        self.calls.append(("run_start", {"run_dir": run_dir, "scene": config["scene"]["name"]}))

    @hookimpl
    def on_stage_end(self, stage, seconds):
        self.calls.append(("stage_end", {"stage": stage, "seconds": seconds}))

    @hookimpl
    def on_training_step(self, source, model, step, total_steps, loss, val_loss):
        self.calls.append(("training_step", {"source": source, "model": model}))

    @hookimpl
    def on_artefact_written(self, path, kind):
        self.calls.append(("artefact", {"path": path, "kind": kind}))

    @hookimpl
    def on_run_end(self, run_dir, metrics, status):
        self.calls.append(("run_end", {"status": status, "metrics_status": metrics["status"]}))

    def names(self, event):
        return [c[1] for c in self.calls if c[0] == event]


class CountingSimulator(AnalyticSimulator):
    renders = 0

    def render(self, geometry):
        type(self).renders += 1
        return super().render(geometry)


class BrokenModel(InterpFieldModel):
    def fit(self, field, validation=None, on_step=None):
        raise RuntimeError("a bug in a plugin")


def plugins(**factories):
    """A plugin module registering the given simulator and/or model factory in-process."""
    module = types.ModuleType("test_plugins_module")

    @hookimpl
    def register_simulators(register):
        if "simulator" in factories:
            register("counting", factories["simulator"], config=AnalyticConfig)

    @hookimpl
    def register_field_models(register):
        if "model" in factories:
            register("broken", factories["model"], config=InterpConfig)

    module.register_simulators = register_simulators
    module.register_field_models = register_field_models
    return module


def pipeline(run_dir, config, host):
    """The engine running ``config``'s plan in ``run_dir``."""
    return Pipeline(make_plan(config, host), run_dir, host)


def compose(overrides, host):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf

    from nlosfw.common.resources import config_dir
    from nlosfw.compose import ensure_resolvers, register_configs

    register_configs(host)
    ensure_resolvers()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        cfg = hydra_compose(config_name="config", overrides=list(overrides))
    GlobalHydra.instance().clear()
    return OmegaConf.to_container(cfg, resolve=True)


@pytest.fixture()
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_lifecycle_hooks_follow_a_run(tmp_path, cache_dir):
    tracker = Tracker()
    host = load_plugins(extra=[("tracking-plugin", "tracker", tracker)])
    run_dir = tmp_path / "run"
    pipeline(run_dir, compose(TINY, host), host).run()
    events = [c[0] for c in tracker.calls]
    assert events[0] == "run_start" and events[-1] == "run_end"
    assert tracker.names("run_start")[0] == {"run_dir": str(run_dir), "scene": "tiny"}
    assert [s["stage"] for s in tracker.names("stage_end")] == [
        "capture", "transform", "fit", "predict", "reconstruct", "report"]
    written = {Path(a["path"]).relative_to(run_dir).as_posix() for a in tracker.names("artefact")}
    on_disk = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()}
    # every file of the run was announced, and nothing else (but the run's marker, which
    # lists them: nlosfw.pipeline.lifecycle)
    assert written == on_disk - {MARKER_NAME}
    assert set(json.loads((run_dir / MARKER_NAME).read_text())["files"]) == written
    assert tracker.names("run_end") == [{"status": "completed", "metrics_status": "completed"}]
    assert {s["source"] for s in tracker.names("training_step")} <= {"interp"}


def test_a_crashing_plugin_leaves_a_failed_record(tmp_path, cache_dir):
    tracker = Tracker()
    host = load_plugins(extra=[("tracking-plugin", "tracker", tracker),
                               ("broken-plugin", "broken", plugins(model=BrokenModel))])
    run_dir = tmp_path / "run"
    with pytest.raises(RuntimeError, match="a bug in a plugin"):
        pipeline(run_dir, compose([*TINY[:1], "model=broken", *TINY[2:]], host), host).run()
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["status"] == "failed" and "capture" in metrics["timings"]
    assert tracker.names("run_end") == [{"status": "failed", "metrics_status": "failed"}]


def test_noisy_scene_renders_the_transport_once(tmp_path, cache_dir):
    host = load_plugins(extra=[("counting-plugin", "counting",
                                plugins(simulator=CountingSimulator))])
    config = compose([*TINY, "simulator=counting", "scene.noise.model=poisson",
                      "scene.noise.photons=1e5", "stop_after=predict"], host)
    CountingSimulator.renders = 0
    pipeline(tmp_path / "a", config, host).run()
    assert CountingSimulator.renders == 1
    metrics = json.loads((tmp_path / "a" / "metrics.json").read_text())
    denoising = metrics["field"]["interp"]["denoising"]
    assert denoising["noisy_relative_l2"] > 0.01  # 1e5 photons: visibly noisy
    # a second run finds both captures (clean and noisy) in the cache
    pipeline(tmp_path / "b", config, host).run()
    assert CountingSimulator.renders == 1
    assert json.loads((tmp_path / "b" / "metrics.json").read_text())["capture"]["cache_hit"]


def test_mesh_file_contents_and_plugin_version_are_part_of_the_cache_key(tmp_path, cache_dir):
    trimesh = pytest.importorskip("trimesh")
    from nlosfw.pipeline.capture_stage import simulation_key
    from nlosfw.pipeline.plan import plugin_version
    from nlosfw.plugins import PluginKind
    from nlosfw.simulate.scene import scene_from_config

    host = load_plugins()
    simulator = host.registry.create("simulator", "analytic")
    version = plugin_version(host, PluginKind.SIMULATOR, "analytic")
    mesh_path = tmp_path / "shape.stl"
    trimesh.creation.box(extents=(0.2, 0.2, 0.2)).export(mesh_path)
    config = fixtures.tiny_scene_config()
    config["geometry"] = [{"type": "mesh", "path": str(mesh_path), "position": [0, 0, 0.6]}]
    scene = scene_from_config(config)
    before = simulation_key("analytic", version, simulator, scene)
    assert simulation_key("analytic", version, simulator, scene) == before
    trimesh.creation.box(extents=(0.3, 0.2, 0.2)).export(mesh_path)   # same path, new shape
    assert simulation_key("analytic", version, simulator, scene) != before
    assert version.startswith("nlosfw==")
    assert simulation_key("analytic", "nlosfw==0", simulator, scene) != simulation_key(
        "analytic", version, simulator, scene)


def test_corrupt_cache_entries_are_recomputed(tmp_path):
    cache = Cache(tmp_path)
    capture = fixtures.tiny_capture()
    calls = []

    def compute():
        calls.append(1)
        return capture

    first, hit = cache.get_or_compute("captures", "0" * 64, compute, write_capture, read_capture)
    assert not hit and len(calls) == 1
    again, hit = cache.get_or_compute("captures", "0" * 64, compute, write_capture, read_capture)
    assert hit and len(calls) == 1
    np.testing.assert_array_equal(again.H, capture.H)
    entry = tmp_path / "captures" / f"{'0' * 64}.hdf5"
    data = bytearray(entry.read_bytes())
    data[len(data) // 2] ^= 0xFF                      # flip one byte
    entry.write_bytes(bytes(data))
    healed, hit = cache.get_or_compute("captures", "0" * 64, compute, write_capture, read_capture)
    assert not hit and len(calls) == 2
    np.testing.assert_array_equal(healed.H, capture.H)


def test_a_random_scan_end_to_end(tmp_path, cache_dir):
    """``split.pattern=random``: models fit the scattered samples, raw images the kept points
    (the full grid with zeros elsewhere), and the split is recorded."""
    from nlosfw.transform.field_io import read_phasor_field

    host = load_plugins()
    overrides = [*TINY[:-1], "reconstruction.n_depths=8", "split.pattern=random",
                 "split.spatial_fraction=0.25", "split.seed=7", "output.keep=[fields]"]
    pipeline(tmp_path / "run", compose(overrides, host), host).run()
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["split"] == {"pattern": "random", "spatial_step": 2, "spatial_fraction": 0.25,
                                "seed": 7, "wall_samples": 256, "train_samples": 64,
                                "undersampling": 4.0, "train_frequencies": 18,
                                "heldout_frequencies": 3}
    raw = read_phasor_field(tmp_path / "run" / "fields" / "raw.hdf5")
    true = read_phasor_field(tmp_path / "run" / "fields" / "true.hdf5")
    kept = np.any(raw.values != 0, axis=0)
    assert kept.sum() == 64
    np.testing.assert_array_equal(raw.values[:, kept], true.values[:, kept])
    scores = metrics["reconstruction"]["sources"]
    assert set(scores) == {"true", "raw", "interp"}
    # a quarter of the tiny scene's samples: Clough-Tocher fills the gaps better than
    # imaging the kept samples alone (32.2 against 24.1 dB when written)
    assert scores["raw"]["psnr"] > 20 and scores["interp"]["psnr"] > scores["raw"]["psnr"] + 4
class RecordingImager(FFTImager):
    """The fft imager, recording every on_progress call of each reconstruction."""

    calls: list[list[tuple[int, int]]] = []

    def reconstruct(self, field, voxels, on_progress=None):
        record: list[tuple[int, int]] = []
        type(self).calls.append(record)

        def forward(done, total):
            record.append((done, total))
            on_progress(done, total)

        return super().reconstruct(field, voxels,
                                   on_progress=None if on_progress is None else forward)


class LegacyImager(FFTImager):
    """An imager written before ``on_progress`` existed."""

    def reconstruct(self, field, voxels):  # the signature before on_progress
        return super().reconstruct(field, voxels)


def imager_plugin(name, factory):
    module = types.ModuleType(f"imager_{name}")

    @hookimpl
    def register_imagers(register):
        register(name, factory, config=FFTImagerConfig)

    module.register_imagers = register_imagers
    return module


def test_reconstruction_reports_progress_per_depth_plane(tmp_path, cache_dir):
    RecordingImager.calls = []
    host = load_plugins(extra=[("rec-plugin", "rec", imager_plugin("recording", RecordingImager))])
    pipeline(tmp_path / "run", compose([*TINY, "imager=recording"], host), host).run()
    # true, raw and interp from every frequency (4 depth planes each, reported one by one),
    # then each of them from two single frequencies (not reported: they are quick)
    full = [c for c in RecordingImager.calls if c]
    assert full == [[(1, 4), (2, 4), (3, 4), (4, 4)]] * 3
    assert len(RecordingImager.calls) == 3 + 3 * 2


def test_an_imager_without_on_progress_still_runs(tmp_path, cache_dir):
    host = load_plugins(extra=[("old-plugin", "old", imager_plugin("legacy", LegacyImager))])
    run_dir = tmp_path / "run"
    pipeline(run_dir, compose([*TINY, "imager=legacy"], host), host).run()
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["status"] == "completed"
    assert set(metrics["reconstruction"]["sources"]) == {"true", "raw", "interp"}


def test_output_keep_decides_which_large_files_are_written(tmp_path, cache_dir):
    host = load_plugins()
    runs = {}
    for i, keep in enumerate(("[]", "[fields,reconstructions]")):
        run_dir = runs[keep] = tmp_path / f"run{i}"
        pipeline(run_dir, compose([*TINY, f"output.keep={keep}"], host), host).run()
    nothing = {p.relative_to(runs["[]"]).as_posix() for p in runs["[]"].rglob("*")
               if p.is_file()}
    # the small files always: the config, metrics, the page, the run's marker of its files
    assert nothing == {"config.yaml", "metrics.json", "metrics.schema.json", "report.html",
                       ".nlosfw-run.json"}
    both = {p.relative_to(runs["[fields,reconstructions]"]).as_posix()
            for p in runs["[fields,reconstructions]"].rglob("*") if p.is_file()}
    assert both == nothing | {f"{d}/{s}.hdf5" for d in ("fields", "reconstructions")
                              for s in ("true", "raw", "interp")}

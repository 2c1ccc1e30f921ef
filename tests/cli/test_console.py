"""Progress reports, the console's log filter and the run overview."""

from __future__ import annotations

import logging
import threading

from nlosfw.cli.console import ConsoleFilter
from nlosfw.cli.overview import changed_options, run_plan, single_frequency_count
from nlosfw.common.config import config_from_mapping, config_to_dict
from nlosfw.common.files import format_bytes
from nlosfw.common.logs import FILE_ONLY
from nlosfw.common.progress import ProgressCounter, accepts_progress
from nlosfw.pipeline.settings import RunSettings
from nlosfw.plugins import load_plugins
from nlosfw.simulate.builtin_scenes import builtin_scene


def test_progress_counter_counts_every_unit_from_many_threads():
    calls: list[tuple[int, int]] = []
    counter = ProgressCounter(8 * 250, lambda done, total: calls.append((done, total)))

    def work():
        for _ in range(250):
            counter.advance()

    threads = [threading.Thread(target=work) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert counter.done == 2000 and len(calls) == 2000
    assert [d for d, _ in calls] == list(range(1, 2001))      # reported in order, no gaps
    assert {t for _, t in calls} == {2000}
    silent = ProgressCounter(3, None)
    silent.advance(5)
    assert silent.done == 3                                    # never beyond the total


def test_accepts_progress_reads_the_signature():
    def new(field, voxels, on_progress=None): ...
    def old(field, voxels): ...
    def anything(field, voxels, **options): ...

    assert accepts_progress(new) and accepts_progress(anything)
    assert not accepts_progress(old) and not accepts_progress(print)


def _record(name: str, level: int, **extra) -> logging.LogRecord:
    record = logging.LogRecord(name, level, __file__, 1, "message", None, None)
    record.__dict__.update(extra)
    return record


def test_the_console_shows_nlosfw_records_and_any_error_only():
    keep = ConsoleFilter().filter
    assert keep(_record("nlosfw.pipeline.engine", logging.INFO))
    assert keep(_record("nlosfw_torch.backend", logging.WARNING))        # our plugins too
    assert not keep(_record("jax._src.xla_bridge", logging.INFO))        # "no TPU"
    assert not keep(_record("jax._src.xla_bridge", logging.WARNING))
    assert not keep(_record("matplotlib.font_manager", logging.INFO))
    assert not keep(_record("py.warnings", logging.WARNING))
    assert keep(_record("hydra", logging.ERROR))
    assert not keep(_record("nlosfw.pipeline.files", logging.INFO, **FILE_ONLY))


def _config(**settings):
    host = load_plugins()
    config = {**config_to_dict(config_from_mapping(RunSettings, settings)),
              "scene": config_to_dict(builtin_scene("tiny")),
              "simulator": {"name": "analytic", "seed": 0, "patch_size": 0.02,
                            "max_pairs": 1000000},
              "transform": {"name": "fft", **config_to_dict(
                  host.registry.get("transform", "fft").make_config({}))},
              "model": {"name": "interp", "extrapolation": "cubic"},
              "imager": {"name": "fft"}}
    return host, config


def test_changed_options_are_those_that_differ_from_each_default():
    host, config = _config(split={"spatial_step": 4},
                           compare={"pe": {"name": "nearest",
                                           "frequency_interpolation": "nearest"}})
    config["scene"]["noise"]["jitter_ps"] = 20.0
    assert changed_options(config, host) == [
        "simulator.patch_size=0.02", "model.extrapolation=cubic", "split.spatial_step=4",
        "compare.pe.name=nearest", "compare.pe.frequency_interpolation=nearest",
        "scene.noise.jitter_ps=20.0"]
    _, plain = _config()
    plain["simulator"]["patch_size"] = 0.01
    plain["model"].pop("extrapolation")
    assert changed_options(plain, host) == []


def test_the_plan_counts_reconstructions_and_says_why():
    picked = {"scene": "tiny", "simulator": "analytic", "transform": "fft",
              "model": "siren_torch", "imager": "rsd"}
    settings = config_from_mapping(RunSettings, {"compare": {"pe": {"name": "pe_torch"}}})
    assert run_plan(picked, settings) == [
        "simulate tiny (analytic) → phasor field (fft) → fit siren_torch, interp, pe_torch → "
        "predict → 15 reconstructions (rsd)",
        "= 5 fields [true: the reference, raw: the training samples, model: siren_torch, "
        "interp: the baseline, pe: pe_torch] × (all frequencies + 2 single frequencies "
        "(training, held out))"]
    no_heldout = config_from_mapping(RunSettings, {"split": {"spectral": "none"}})
    assert single_frequency_count(no_heldout) == 1
    assert run_plan({**picked, "model": "interp"}, no_heldout)[0].endswith(
        "fit interp → predict → 6 reconstructions (rsd)")
    early = config_from_mapping(RunSettings, {"stop_after": "fit",
                                              "capture": {"path": "c.hdf5"}})
    assert run_plan(picked, early) == [
        "read c.hdf5 → phasor field (fft) → fit siren_torch, interp (stop after fit)"]


def test_format_bytes():
    assert [format_bytes(n) for n in (0, 999, 1000, 7_212_345, 57_261_952, 3 * 10**9)] == [
        "0 B", "999 B", "1.0 kB", "7.2 MB", "57.3 MB", "3.0 GB"]

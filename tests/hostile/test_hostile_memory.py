"""The memory estimate counts the program itself where a run's peak is compared with it,
and not where it is compared with the memory left beside the program; its parts are the
engine's arrays and what each field model estimates of itself."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import memory
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.memory import MemoryEstimate
from nlosfw.model.neural import memory as neural_memory
from nlosfw.pipeline.budget import check_memory, memory_summary
from nlosfw.testing import fixtures
from tests.planned import TINY, planned


@pytest.fixture(scope="module")
def interp():
    return planned(TINY)


def test_process_memory_grows_with_an_array_this_process_holds():
    # measured in a fresh interpreter: in the suite's own process, malloc may hand the
    # block pages that an earlier test freed and that are still resident, and then the
    # resident memory does not grow (a CI run saw exactly that)
    code = ("import numpy as np; from nlosfw.pipeline.budget import process_memory; "
            "before = process_memory(); block = np.ones(50_000_000 // 8); "
            "print(before, process_memory() - before, block.nbytes)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    before, grown, nbytes = (int(word) for word in done.stdout.split())
    assert before > 10_000_000                        # Python and numpy at least
    assert nbytes == 50_000_000 and grown >= 0.9 * nbytes


def test_the_program_is_a_part_of_the_summary_not_of_the_check(interp):
    arrays = interp.memory
    assert [p.what for p in arrays.parts] == ["the transient H", "the phasor transform",
                                              "the fields imaged", "the voxels and images",
                                              "the field's spectrum", "the kernels' blocks"]
    summary = memory_summary(arrays)
    assert "the program" in summary
    number, unit = summary.rsplit("the program ", 1)[1].split()[:2]
    scale = {"B": 1e-6, "kB": 1e-3, "MB": 1.0, "GB": 1e3, "TB": 1e6}[unit.rstrip(",;)")]
    assert float(number) * scale > 10   # MB: Python and numpy at least (GB in a grown worker)
    # the memory available is what is left beside the program: the check leaves it out
    check_memory(arrays, available=int(arrays.total) + 1)


# ------------------------------------------------------------ neural models' own memory
NEURAL = (*TINY[:-1], "model=siren_torch", "model.hidden=[64,32,16]", "model.batch_size=512",
          "model.steps=10", "model.eval_every=1")


def _parts(estimate: MemoryEstimate) -> dict[str, float]:
    return {p.what: p.nbytes for p in estimate.merged()}


def test_a_neural_model_adds_its_runtime_and_training_by_the_documented_formula(
        interp, monkeypatch):
    plan = planned(NEURAL)
    parts = _parts(plan.memory)
    for what in ("the transient H", "the phasor transform"):     # one field more, not these
        assert parts[what] == _parts(interp.memory)[what]
    torch = neural_memory.BACKENDS["torch"]
    samples = 21 * 16 * 16                         # F · S · L of the tiny 16 × 16 wall
    assert parts["the model's runtime"] == torch.working     # torch imported by the plan
    assert parts["the model's training"] == pytest.approx(
        torch.per_sample * samples + torch.per_activation * 512 * (64 + 32 + 16))
    assert parts["the training history"] == 10 * neural_memory.HISTORY_ENTRY
    whys = {p.what: p.why for p in plan.memory.parts}
    assert whys["the model's training"].startswith("model (siren_torch): 5376 samples")
    # a backend not imported yet is its import as well
    monkeypatch.delitem(sys.modules, "torch")
    assert neural_memory.runtime_part("torch").nbytes == torch.imported + torch.working


def test_interp_adds_nothing_and_a_batch_is_at_most_the_samples(interp):
    from nlosfw.model.neural import FieldMode, FieldShape, SirenFieldConfig

    assert "the model's runtime" not in _parts(interp.memory)
    config = SirenFieldConfig(batch_size=10**9, hidden=(8,), steps=1)
    parts = _parts(neural_memory.network_memory(config, "jax",
                                                FieldShape(FieldMode.multi, (4, 4), 1), 100.0))
    jax = neural_memory.BACKENDS["jax"]
    assert parts["the model's training"] == jax.per_sample * 100 + jax.per_activation * 100 * 8
    assert _parts(neural_memory.network_memory(config, "no_such_backend", FieldShape(
        FieldMode.multi, (4, 4), 1), 100.0)) == {}


def test_a_runtime_shared_by_two_models_is_counted_once():
    plan = planned((*NEURAL, "+compare.b={name:siren_torch,hidden:[8],batch_size:4}",
                    "+compare.c={name:pe_jax,hidden:[8],batch_size:4}"))
    runtimes = [p for p in plan.memory.merged() if p.what == "the model's runtime"]
    torch, jax = neural_memory.BACKENDS["torch"], neural_memory.BACKENDS["jax"]
    assert sorted(p.nbytes for p in runtimes) == sorted([torch.working, jax.working])
    assert sorted(p.why for p in runtimes) == ["jax and its first training",
                                               "torch and its first training"]
    counted = [p for p in plan.memory.parts if p.what == "the model's runtime"]
    assert len(counted) == 3                   # three models' estimates, two runtimes
    whys = [p.why for p in plan.memory.parts if p.what == "the model's training"]
    assert [w.split(":")[0] for w in whys] == ["model (siren_torch)", "compare.b (siren_torch)",
                                               "compare.c (pe_jax)"]


def test_the_check_refuses_a_run_whose_arrays_fit_but_whose_model_does_not(interp):
    plan = planned(NEURAL)
    arrays = int(interp.memory.total)
    check_memory(interp.memory, available=arrays + 1)
    with pytest.raises(ConfigError, match=r"this run needs about .*, most of it for the "
                                          r"model's (runtime \(torch|training \(model)"):
        check_memory(plan.memory, available=arrays + 1)


# ------------------------------------------- a defined dataset larger than the memory left
def _capture_with_a_4_gb_sensor_grid(path: Path) -> Path:
    write_capture(path, fixtures.tiny_capture())
    with h5py.File(path, "a") as f:      # 4 GB of sensor points declared, nothing stored
        del f["sensor_grid_xyz"]
        f.create_dataset("sensor_grid_xyz", shape=(1000, 1000, 500), dtype="f8",
                         chunks=(1, 10, 10))
    assert path.stat().st_size < 1_000_000
    return path


def test_a_defined_4_gb_dataset_is_refused_before_it_is_read_when_less_is_available(
        tmp_path, monkeypatch):
    path = _capture_with_a_4_gb_sensor_grid(tmp_path / "c.hdf5")
    monkeypatch.setattr(memory, "available_memory", lambda: 1_000_000_000)
    with pytest.raises(DataError) as caught:
        read_capture(path)
    assert str(caught.value) == (
        f"{path}: dataset 'sensor_grid_xyz' declares 4.0 GB (shape [1000, 1000, 500] of "
        "float64), more than the 1.0 GB of memory available; refused before reading it")


def test_the_command_line_refuses_it_in_one_line_exit_2_and_writes_nothing(
        workdir, tools, monkeypatch):
    path = _capture_with_a_4_gb_sensor_grid(workdir / "huge grid.hdf5")
    monkeypatch.setattr(memory, "available_memory", lambda: 1_000_000_000)
    result = tools.run(f"capture.path={path}", *tools.QUICK[1:])
    assert result.returncode == 2
    line = tools.one_error_line(result)
    assert f"{path}: dataset 'sensor_grid_xyz' declares 4.0 GB" in line
    assert line.endswith("more than the 1.0 GB of memory available; refused before reading it")
    assert not (workdir / "outputs").exists() and not (workdir / "cache").exists()

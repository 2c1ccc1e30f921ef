"""The memory estimate counts the program itself where a run's peak is compared with it,
and not where it is compared with the memory left beside the program (issue 20)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.common import memory
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.pipeline import model_budget
from nlosfw.pipeline.budget import check_memory, estimate_memory, memory_summary
from nlosfw.testing import fixtures

CONFIG = {"scene": {"wall": {"resolution": [16, 16]}, "time": {"bins": 512}},
          "transform": {"name": "fft", "n_frequencies": 21}, "model": {"name": "interp"},
          "reconstruction": {"n_depths": 4}}


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


def test_the_program_is_a_part_of_the_estimate_only_when_asked():
    arrays = estimate_memory(CONFIG)
    with_program = estimate_memory(CONFIG, program=True)
    assert [p.what for p in with_program] == [p.what for p in arrays] + ["the program"]
    assert with_program[-1].nbytes > 10_000_000
    assert "the program" in memory_summary(CONFIG)
    # the memory available is what is left beside the program: the check leaves it out
    check_memory(CONFIG, available=int(sum(p.nbytes for p in arrays)) + 1)


# ------------------------------------------------------------ neural models' own memory
NEURAL = {**CONFIG, "model": {"name": "siren_torch", "hidden": [64, 32, 16], "batch_size": 512,
                              "steps": 10, "eval_every": 1}}
TORCH = ("nlosfw_torch", "torch")


def _requires(name: str) -> tuple[str, ...]:
    """A registry's declared requirements, standing in for plugin_requires(host)."""
    return {"siren_torch": TORCH, "pe_jax": ("nlosfw_jax", "jax", "optax")}.get(name, ())


def test_a_neural_model_adds_its_runtime_and_training_by_the_documented_formula(monkeypatch):
    monkeypatch.setattr(model_budget, "imported", lambda module: False)
    arrays = estimate_memory(NEURAL)
    parts = estimate_memory(NEURAL, requires=_requires)
    assert parts[:len(arrays)] == arrays and len(parts) == len(arrays) + 2
    runtime, training = parts[-2:]
    torch = model_budget.BACKENDS["torch"]
    samples = 21 * 16 * 16                         # F · S · L of CONFIG's 16 × 16 wall
    assert runtime.what == "the model's runtime"
    assert runtime.nbytes == torch.imported + torch.working
    assert training.nbytes == pytest.approx(torch.per_sample * samples
                                            + torch.per_activation * 512 * (64 + 32 + 16))
    # an imported backend is the program's memory already: only its working memory is added
    monkeypatch.setattr(model_budget, "imported", lambda module: True)
    assert estimate_memory(NEURAL, requires=_requires)[-2].nbytes == torch.working


def test_interp_and_unknown_models_add_nothing_and_a_batch_is_at_most_the_samples():
    interp = estimate_memory(CONFIG, requires=_requires)
    assert [p.what for p in interp] == [p.what for p in estimate_memory(CONFIG)]
    assert "the model's runtime" not in [p.what for p in estimate_memory(NEURAL)]
    data, activations = model_budget.training_bytes({"batch_size": 10**9, "hidden": [8]},
                                                    "jax", 100.0)
    jax = model_budget.BACKENDS["jax"]
    assert (data, activations) == (jax.per_sample * 100, jax.per_activation * 100 * 8)


def test_a_runtime_shared_by_two_models_is_counted_once(monkeypatch):
    monkeypatch.setattr(model_budget, "imported", lambda module: False)
    config = {**NEURAL, "compare": {"b": {"name": "siren_torch", "hidden": [8],
                                         "batch_size": 4},
                                    "c": {"name": "pe_jax", "hidden": [8], "batch_size": 4}}}
    runtime = estimate_memory(config, requires=_requires)[-2]
    torch, jax = model_budget.BACKENDS["torch"], model_budget.BACKENDS["jax"]
    assert runtime.nbytes == torch.imported + torch.working + jax.imported + jax.working
    assert runtime.why == "jax and torch and its first training"


def test_the_check_refuses_a_run_whose_arrays_fit_but_whose_model_does_not():
    arrays = int(sum(p.nbytes for p in estimate_memory(NEURAL)))
    check_memory(NEURAL, available=arrays + 1)
    with pytest.raises(ConfigError, match=r"this run needs about .*, most of it for the "
                                          r"model's runtime \(torch"):
        check_memory(NEURAL, available=arrays + 1, requires=_requires)


def test_the_backend_is_read_from_the_plugins_declared_requirements_without_importing_it():
    code = ("import sys; from nlosfw.plugins import load_plugins; "
            "from nlosfw.pipeline.model_budget import plugin_requires, backend_of; "
            "r = plugin_requires(load_plugins()); "
            "print(backend_of(r('siren_torch')), backend_of(r('siren_jax')), "
            "backend_of(r('interp')), list(r('no_such_model')), "
            "'torch' in sys.modules, 'jax' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, check=True)
    assert done.stdout.split() == ["torch", "jax", "None", "[]", "False", "False"]


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

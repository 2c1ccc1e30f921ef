"""The neural hidden volume's validation points, kept step and aligned operator arrays (no
backend needed), and its refusal of an operator larger than the memory left (with torch)."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.common import ConfigError, FitError
from nlosfw.model import NeuralVolumeConfig
from nlosfw.model.hybrid import BestStep, aligned_empty
from nlosfw.model.physics import validation_split
from nlosfw.plugins import load_plugins
from nlosfw.plugins.networks import NEURAL_VOLUME_TEST_CONFIG
from nlosfw.testing.checks_model import fit_fixture


def test_validation_split_holds_out_a_seeded_fraction_of_the_wall_points():
    train, val = validation_split((8, 8), 0.1, seed=3)
    assert val is not None and train.shape == val.shape == (8, 8)
    assert val.sum() == 6 and train.sum() == 58            # round(0.1 * 64)
    assert np.array_equal(train + val, np.ones((8, 8)))     # disjoint, every point once
    again, val_again = validation_split((8, 8), 0.1, seed=3)
    assert np.array_equal(val, val_again)
    _, other = validation_split((8, 8), 0.1, seed=4)
    assert not np.array_equal(val, other)


@pytest.mark.parametrize("shape, fraction", [((3, 3), 0.4), ((8, 8), 0.0), ((4, 4), 0.01)])
def test_no_validation_for_few_points_or_a_zero_fraction(shape, fraction):
    train, val = validation_split(shape, fraction, seed=0)
    assert val is None and np.array_equal(train, np.ones(shape))


def test_best_step_keeps_the_lowest_error_and_stops_after_patience():
    best = BestStep(patience=2)
    for step, error in enumerate([1.0, 0.5, 0.7, 0.6]):
        best.offer(step, error, f"albedo {step}")
        if best.stop(step):
            break
    assert (best.step, best.error, best.albedo, best.validation) == (1, 0.5, "albedo 1", 0.5)
    assert step == 3                                       # two steps without improvement


def test_best_step_without_validation_keeps_the_latest_and_never_stops():
    best = BestStep(patience=1)
    for step in range(5):
        best.offer(step, None, step)
        assert not best.stop(step)
    assert best.albedo == 4 and best.validation is None


def test_best_step_with_a_window_keeps_the_mean_of_the_last_steps_up_to_the_best():
    """Albedos 0, 10, 20, ... offered with errors falling to step 4, then rising: a window of
    3 keeps the mean of steps 2, 3 and 4 (30); the first steps average what there is."""
    best = BestStep(patience=0, window=3)
    for step, error in enumerate([5.0, 4.0, 3.0, 2.0, 1.0, 1.5, 0.9 + 1.0]):
        best.offer(step, error, np.full(2, 10.0 * step))
        if step == 1:
            np.testing.assert_allclose(best.albedo, [5.0, 5.0])    # mean of 0 and 10
    assert best.step == 4 and best.error == 1.0
    np.testing.assert_allclose(best.albedo, [30.0, 30.0])
    assert len(best.recent) == 3                               # steps 4, 5, 6 are held


def test_best_step_with_a_window_keeps_the_offered_arrays_unchanged():
    offered = [np.full(2, float(k)) for k in range(3)]
    best = BestStep(patience=0, window=2)
    for step, albedo in enumerate(offered):
        best.offer(step, None, albedo)
    np.testing.assert_allclose(best.albedo, [1.5, 1.5])
    assert [float(a[0]) for a in offered] == [0.0, 1.0, 2.0]


@pytest.mark.parametrize("option, value", [("validation_fraction", 0.5),
                                           ("validation_fraction", -0.1), ("patience", -1),
                                           ("average_steps", 0)])
def test_bad_validation_options_name_the_option(option, value):
    with pytest.raises(ConfigError, match=option):
        NeuralVolumeConfig(network="siren", **{option: value})


def test_an_operator_larger_than_the_memory_left_is_refused_in_one_line(monkeypatch):
    """Before its spectra are built, the fit names the operator's size, the memory left and
    the options that make it smaller."""
    pytest.importorskip("torch")
    monkeypatch.setattr("nlosfw.model.hybrid.volume.available_memory", lambda: 1000)
    model = load_plugins().registry.create("model", "neural_volume_torch",
                                           dict(NEURAL_VOLUME_TEST_CONFIG))
    with pytest.raises(FitError) as err:
        model.fit(fit_fixture(physical=True))
    message = str(err.value)
    assert "\n" not in message and "but 1.0 kB are available" in message, message
    assert "model.prior.fit_frequencies" in message and "depth planes" in message, message


@pytest.mark.parametrize("shape, dtype", [((3, 5, 7), np.complex64), ((1,), np.complex128),
                                          ((4, 6, 9, 11), np.float32), ((1, 3), np.float32)])
def test_aligned_empty_starts_on_a_64_byte_boundary(shape, dtype):
    """aligned_empty (plane_stack's arrays) is C-contiguous, of the shape and dtype asked,
    starts on a 64-byte boundary and owns memory no other array shares."""
    arrays = [aligned_empty(shape, dtype) for _ in range(3)]
    for a in arrays:
        assert a.shape == shape and a.dtype == np.dtype(dtype) and a.flags.c_contiguous
        assert a.ctypes.data % 64 == 0
        a[...] = 1
    assert not np.shares_memory(arrays[0], arrays[1])

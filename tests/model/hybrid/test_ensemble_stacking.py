"""The stacked ensemble's pieces that need no network: the convex weights, the held-out
kept points (the neural volume's own) and the subset fields the members fit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from nlosfw.common import ConfigError, DataError
from nlosfw.common.config import config_from_mapping
from nlosfw.evaluation import SpatialSampling, split_field
from nlosfw.model.hybrid.ensemble_config import EnsembleConfig
from nlosfw.model.hybrid.stacking import (
    held_out_points,
    simplex_weights,
    stacking_problem,
    subset_field,
)
from nlosfw.model.physics import validation_split, wall_samples
from nlosfw.testing import fixtures


def _brute_force(gram: np.ndarray, target: np.ndarray, n: int = 200) -> float:
    """The smallest w' G w - 2 b' w over a fine grid of the simplex (3 members)."""
    best = np.inf
    for i, j in itertools.product(range(n + 1), repeat=2):
        if i + j > n:
            continue
        w = np.array([i, j, n - i - j]) / n
        best = min(best, float(w @ gram @ w - 2 * target @ w))
    return best


@pytest.mark.parametrize("seed", range(6))
def test_simplex_weights_are_the_constrained_minimiser(seed):
    """Random member fields against a random target: the weights lie on the simplex and
    their objective is no worse than the best of a fine grid over the simplex (nor than any
    single member's)."""
    rng = np.random.default_rng(seed)
    fields = rng.standard_normal((3, 40)) + 1j * rng.standard_normal((3, 40))
    measured = rng.standard_normal(40) + 1j * rng.standard_normal(40)
    gram, target, _ = stacking_problem(fields, measured)
    w = simplex_weights(gram, target)
    assert np.all(w >= 0) and abs(w.sum() - 1) < 1e-12
    value = float(w @ gram @ w - 2 * target @ w)
    assert value <= _brute_force(gram, target) + 1e-9
    assert value <= min(gram[k, k] - 2 * target[k] for k in range(3)) + 1e-12


def test_a_member_equal_to_the_target_takes_every_weight():
    """When one member is the measured field the weights are exactly one-hot on it."""
    rng = np.random.default_rng(0)
    measured = rng.standard_normal((5, 12)) + 1j * rng.standard_normal((5, 12))
    fields = np.stack([measured + 0.3 * rng.standard_normal(measured.shape), measured,
                       0.5 * measured])
    w = simplex_weights(*stacking_problem(fields, measured)[:2])
    assert w.tolist() == [0.0, 1.0, 0.0]


def test_two_members_with_independent_errors_share_the_weight():
    """Two members with independent errors of equal size each get about half."""
    rng = np.random.default_rng(1)
    truth = rng.standard_normal(20000)
    fields = np.stack([truth + rng.standard_normal(truth.size),
                       truth + rng.standard_normal(truth.size)])
    w = simplex_weights(*stacking_problem(fields, truth)[:2])
    assert abs(w[0] - 0.5) < 0.02 and abs(w[1] - 0.5) < 0.02


def test_simplex_weights_refuse_mismatched_shapes():
    with pytest.raises(DataError, match="simplex_weights"):
        simplex_weights(np.eye(2), np.ones(3))


def _field(step: int, pattern: str = "grid"):
    full = fixtures.point_field((0.05, -0.02, 0.5), (32, 32), 1 / 32, np.linspace(2, 4, 6))
    sampling = SpatialSampling(step=step, pattern=pattern, seed=3)
    return split_field(full, sampling, spectral="none").train_field


@pytest.mark.parametrize("pattern", ["grid", "random"])
def test_the_held_out_points_are_the_neural_volumes_validation_points(pattern):
    """The points held out are validation_split's on the samples' canonical grid (what the
    neural volume holds out with the same fraction and seed), mapped back to the field's
    own layout: a tenth of the kept points, all of them kept points."""
    field = _field(4, pattern)
    held = held_out_points(field, 0.1, 7, "test")
    samples = wall_samples(field, "test")
    _, expected = validation_split(samples.layout.shape, 0.1, 7, samples.mask)
    assert np.array_equal(held.canonical, expected.astype(bool))
    assert held.count == round(0.1 * samples.count) == int(expected.sum())
    # the values at the points held out, read in the field's layout and on the grid, agree
    on_grid = held.measured(field)
    in_field = field.values[:, held.validation]
    assert sorted(np.abs(on_grid[0]).tolist()) == sorted(np.abs(in_field[0]).tolist())


def test_the_members_training_field_is_the_kept_points_not_held_out():
    field = _field(4)
    held = held_out_points(field, 0.1, 0, "test")
    trained = subset_field(field, ~held.validation)
    assert trained.grid_shape == (1, field.grid_shape[0] * field.grid_shape[1] - held.count)
    assert np.array_equal(trained.values[:, 0], field.values[:, ~held.validation])
    assert np.array_equal(trained.wall_xyz[0], field.wall_xyz[~held.validation])


def test_too_few_kept_points_to_hold_any_out_is_a_data_error():
    field = _field(16)                                   # 2 x 2 kept points
    with pytest.raises(DataError, match=r"test: 4 kept wall points hold out none"):
        held_out_points(field, 0.1, 0, "test")


def test_ensemble_options_are_checked():
    """One-line errors naming the option: a weight twice or below 0, no member, a TV weight
    set where the members' own replace it, the unused residual prior, no held-out points
    to weigh two members."""
    default = EnsembleConfig()
    assert default.tv_weights == (0.03, 0.1, 0.3) and default.member_count == 4
    for options, option in (({"tv_weights": [0.1, 0.1]}, "tv_weights"),
                            ({"tv_weights": [-0.1]}, "tv_weights"),
                            ({"tv_weights": [], "neural_volume": False}, "tv_weights"),
                            ({"prior": {"tv_weight": 0.1}}, "prior.tv_weight"),
                            ({"residual": {"prior": {"iterations": 3}}}, "residual.prior"),
                            ({"volume": {"validation_fraction": 0.0}},
                             "volume.validation_fraction")):
        with pytest.raises(ConfigError, match=option.replace(".", r"\.")):
            config_from_mapping(EnsembleConfig, options, "model")
    alone = config_from_mapping(EnsembleConfig, {"tv_weights": [], "add_residual": False,
                                                 "volume": {"validation_fraction": 0.0}})
    assert alone.member_count == 1
    assert default.prior_member_config(0.3).tv_weight == 0.3

"""Backend-neutral pieces of the neural fields: presets, encoding, init, normalisation, files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nlosfw.common.errors import ConfigError, DataError, FitError
from nlosfw.model.model_files import read_model_file, write_model_file
from nlosfw.model.neural.catalogue import PRESETS, preset_config
from nlosfw.model.neural.config import NeuralFieldConfig
from nlosfw.model.neural.mlp import (
    SirenFieldConfig,
    count_parameters,
    default_octaves,
    forward_numpy,
    init_parameters,
    network_inputs,
    positional_encoding,
    resolve_architecture,
)
from nlosfw.model.neural.normalisation import FieldNormalisation, estimate_delay
from nlosfw.model.neural.trainer import learning_rate
from nlosfw.testing import fixtures

THESIS_COUNTS = {"thesis_tanh_single": 942, "thesis_pe_single": 914, "thesis_pe_multi": 3938,
                 "thesis_siren": 3362}


@pytest.mark.parametrize("name", sorted(THESIS_COUNTS))
def test_presets_reproduce_table_4_1(name):
    preset = PRESETS[name]
    assert preset.parameters == THESIS_COUNTS[name]
    config = preset_config(name)
    arch = resolve_architecture(preset.family, config, (32, 32), 135)
    assert count_parameters(arch) == THESIS_COUNTS[name]
    shapes = [p.shape for p in init_parameters(arch, 0, seed=0)]
    assert sum(int(np.prod(s)) for s in shapes) == THESIS_COUNTS[name]


def test_preset_shapes_are_the_thesis_networks():
    arch = resolve_architecture("pe", preset_config("thesis_pe_multi"), (32, 32), 135)
    assert arch.layer_shapes == [(21, 32), (32, 32), (32, 32), (32, 32), (32, 2)]
    arch = resolve_architecture("pe", preset_config("thesis_pe_single"), (32, 32), 1)
    assert arch.layer_shapes[0] == (20, 16)
    arch = resolve_architecture("siren", preset_config("thesis_siren"), (32, 32), 135)
    assert arch.layer_shapes[0] == (3, 32) and arch.activation == "sine"
    with pytest.raises(DataError, match="unknown preset"):
        preset_config("nope")


def test_default_octaves_follow_resolution():
    assert default_octaves(32) == 5            # thesis: 2^L closest to 32
    assert default_octaves(64) == 6
    assert default_octaves(45) == 5 and default_octaves(46) == 6
    config = preset_config("thesis_pe_single", octaves=0)
    assert resolve_architecture("pe", config, (16, 24), 1).octaves == round(math.log2(24))


def test_positional_encoding_is_eq_4_3():
    u = np.array([[0.3, -0.7]])
    enc = positional_encoding(u, 3)
    expected = []
    for v in u[0]:
        for level in range(3):
            expected += [math.sin(2**level * math.pi * v), math.cos(2**level * math.pi * v)]
    np.testing.assert_allclose(enc[0], expected, rtol=1e-12)


def test_siren_initialisation_bounds():
    config = SirenFieldConfig(hidden=(40, 40), omega0_first=30.0, omega0_hidden=25.0)
    arch = resolve_architecture("siren", config, (8, 8), 4)
    params = init_parameters(arch, 0, seed=3)
    w0, w1 = params[0], params[2]
    assert np.abs(w0).max() <= 1 / 3 and np.abs(w0).max() > 0.3      # U(-1/n, 1/n), n = 3
    bound = math.sqrt(6 / 40) / 25.0
    assert np.abs(w1).max() <= bound and np.abs(w1).max() > 0.9 * bound
    assert w1.std() == pytest.approx(bound / math.sqrt(3), rel=0.05)          # uniform
    again = init_parameters(arch, 0, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(params, again, strict=True))


def test_single_mode_parameters_have_a_network_axis():
    config = preset_config("thesis_tanh_single")
    arch = resolve_architecture("tanh", config, (32, 32), 7)
    params = init_parameters(arch, 7, seed=0)
    assert params[0].shape == (7, 2, 20)
    assert count_parameters(arch, 7) == 7 * 942
    x = np.random.default_rng(0).uniform(-1, 1, (5, 2)).astype(np.float32)
    out = forward_numpy(arch, params, x)
    assert out.shape == (7, 5, 2)
    single = forward_numpy(arch, [p[2] for p in params], x)
    np.testing.assert_allclose(out[2], single, rtol=1e-12)


def test_normalisation_maps_into_the_open_interval_and_back():
    field = fixtures.point_phasor_field(n=12, frequencies=np.linspace(3, 5, 9)) \
        .replace(wall_xyz=fixtures.wall_grid(12, 2.0) + np.array([0.4, -0.2, 0.0]))
    norm = FieldNormalisation.fit(field, margin=0.9, demodulate=True)
    xy = norm.coords(field.wall_xyz[..., :2])
    assert np.abs(xy).max() == pytest.approx(0.9)
    assert np.abs(norm.freqs(field.frequencies)).max() == pytest.approx(0.9)
    t = norm.targets(field.values, field.frequencies)
    assert np.abs(t).max() == pytest.approx(0.9, rel=1e-6)
    back = norm.values(t, field.frequencies)
    np.testing.assert_allclose(back, field.values, rtol=1e-5, atol=1e-6 * np.abs(t).max()
                               * norm.value_scale)
    again = FieldNormalisation.from_dict(norm.to_dict())
    assert again == norm


def test_estimated_delay_is_the_path_length_of_a_point():
    field = fixtures.point_phasor_field((0.0, 0.0, 0.8), n=1, frequencies=np.linspace(4, 12, 60))
    # laser spot at the wall centre, one sensor at (-0.5, -0.5): path |p - 0| + |p - s|
    s = field.wall_xyz[0, 0]
    path = 0.8 + np.linalg.norm(np.array([0.0, 0.0, 0.8]) - s)
    assert estimate_delay(field.values, field.frequencies) == pytest.approx(path, abs=0.01)


def test_network_inputs_layout():
    config = preset_config("thesis_pe_multi")
    arch = resolve_architecture("pe", config, (32, 32), 10)
    xy = np.array([[0.1, 0.2], [0.3, 0.4]])
    f = np.array([-0.5, 0.5, 0.7])
    x = network_inputs(arch, xy, f)
    assert x.shape == (6, 21)
    np.testing.assert_allclose(x[4, -1], 0.7)                      # row k * P + p
    np.testing.assert_allclose(x[4, :20], positional_encoding(xy[:1], 5)[0], rtol=1e-6)


def test_learning_rate_schedules():
    cosine = NeuralFieldConfig(steps=101, lr=1e-2, lr_schedule="cosine", lr_final=0.1)
    assert learning_rate(cosine, 0) == pytest.approx(1e-2)
    assert learning_rate(cosine, 100) == pytest.approx(1e-3)
    assert learning_rate(cosine, 50) == pytest.approx(1e-2 * (0.1 + 0.9 * 0.5))
    warm = NeuralFieldConfig(steps=100, lr=1e-2, warmup_steps=10)
    assert learning_rate(warm, 0) == pytest.approx(1e-4)
    assert learning_rate(warm, 10) == pytest.approx(1e-2)
    expo = NeuralFieldConfig(steps=11, lr=1.0, lr_schedule="exponential", lr_final=0.01)
    assert learning_rate(expo, 5) == pytest.approx(0.1)


def test_config_validation_is_one_line():
    for bad in ({"margin": 1.0}, {"hidden": []}, {"lr": -1.0}, {"validation_fraction": 0.6}):
        with pytest.raises(ConfigError) as err:
            NeuralFieldConfig(**bad)
        assert "\n" not in str(err.value)


def test_model_files(tmp_path):
    path = tmp_path / "m.anything"
    write_model_file(path, "siren_torch", SirenFieldConfig(), {"p0": np.ones(3)}, {"k": 1})
    header, arrays = read_model_file(path, "siren_torch")
    assert header["k"] == 1 and header["config"]["omega0_first"] == SirenFieldConfig().omega0_first
    np.testing.assert_array_equal(arrays["p0"], np.ones(3))
    with pytest.raises(DataError, match="holds a 'siren_torch'"):
        read_model_file(path, "tanh_jax")
    path.write_bytes(path.read_bytes()[:50])
    with pytest.raises(DataError, match="corrupt"):
        read_model_file(path, "siren_torch")
    with pytest.raises(DataError, match="does not exist"):
        read_model_file(tmp_path / "missing", "siren_torch")
    with pytest.raises(FitError, match="zero"):
        FieldNormalisation.fit(fixtures.smooth_field(n=4).replace(
            values=np.zeros((12, 4, 4))), 0.9)


def test_estimate_delay_is_periodic_across_the_wrap_boundary():
    """A transient at path d gives a delay equal to d modulo the period 1/df (any d)."""
    f = np.linspace(4.0, 8.0, 41)                      # df = 0.1: period 10 m
    period = 10.0
    for d in (1.0, 4.9, 5.1, 6.5, 9.7):                # around and beyond +period/2
        values = np.exp(-2j * np.pi * f * d)[:, None] * np.ones((1, 3))
        tau = estimate_delay(values, f)
        wrapped = (tau - d + period / 2) % period - period / 2
        assert abs(wrapped) < 0.02, (d, tau)
    two = np.exp(-2j * np.pi * f * 4.8)[:, None] + np.exp(-2j * np.pi * f * 5.2)[:, None]
    tau = estimate_delay(two, f)                       # straddles the wrap: 5.0 (mod 10)
    assert abs((tau - 5.0 + period / 2) % period - period / 2) < 0.05

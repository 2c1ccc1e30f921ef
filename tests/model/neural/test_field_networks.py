"""fourier, wire, finer and hashgrid: their parts against closed forms and an
independent brute-force grid lookup, torch against JAX, and parameter counts by hand."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from nlosfw.common.errors import ConfigError, FitError
from nlosfw.model.neural import (
    FieldMode,
    FieldShape,
    FinerFieldConfig,
    FourierFieldConfig,
    HashGridFieldConfig,
    NetworkBuild,
    WireFieldConfig,
    field_network_state,
    hash_grid_layout,
)
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures

NETWORKS = ("fourier", "wire", "finer", "hashgrid")
BACKENDS = ("torch", "jax")


def _backend_module(backend):
    pytest.importorskip(backend)
    if backend == "jax":
        pytest.importorskip("equinox")
    return pytest.importorskip(f"nlosfw_{backend}.networks")


def _to_numpy(out):
    return np.asarray(out.detach().numpy() if hasattr(out, "detach") else out)


def _call(backend, module, x):
    if backend == "torch":
        import torch

        with torch.no_grad():
            return _to_numpy(module(torch.as_tensor(x)))
    import jax.numpy as jnp

    return _to_numpy(module(jnp.asarray(x)))


# --------------------------------------------------------------------------- configs
@pytest.mark.parametrize(("cls", "option", "value"), [
    (FourierFieldConfig, "sigma", 0.0), (FourierFieldConfig, "frequency_sigma", -1.0),
    (WireFieldConfig, "omega0", 0.0), (FinerFieldConfig, "first_bias_scale", -1.0),
    (HashGridFieldConfig, "log2_table_size", 30), (HashGridFieldConfig, "finest_resolution", 2),
    (FourierFieldConfig, "frequency_smoothness", -1.0),
    (WireFieldConfig, "smoothness_points", 0)])
def test_bad_options_are_one_line_config_errors(cls, option, value):
    with pytest.raises(ConfigError, match=option) as err:
        cls(**{option: value})
    assert "\n" not in str(err.value)


def test_hash_grid_levels_are_geometric_and_tables_capped():
    config = HashGridFieldConfig(levels=4, base_resolution=2, finest_resolution=16,
                                 log2_table_size=8, features_per_level=3)
    layout = hash_grid_layout(config, FieldShape(FieldMode.multi))
    # b = (16 / 2)^(1/3) = 2: N = 2, 4, 8, 16; (N + 1)^3 = 27, 125, 729, 4913 vs T = 256
    assert layout.resolutions == (2, 4, 8, 16)
    assert layout.table_sizes == (27, 125, 256, 256)
    assert layout.hashed == (False, False, True, True)
    assert (layout.dims, layout.raw_inputs, layout.encoded_dim) == (3, 0, 12)
    flat = hash_grid_layout(HashGridFieldConfig(levels=3, base_resolution=4, encode_frequency=False,
                                                finest_resolution=9),
                            FieldShape(FieldMode.multi))
    # b = 1.5: N = 4, 6, 9 on (x, y); f goes to the MLP as it is
    assert flat.resolutions == (4, 6, 9) and flat.dims == 2 and flat.encoded_dim == 3 * 2 + 1
    auto = HashGridFieldConfig(levels=2, base_resolution=4)
    assert hash_grid_layout(auto, FieldShape(FieldMode.single, (16, 12), 5)).resolutions == (4, 16)
    with pytest.raises(FitError, match="known after fit"):
        hash_grid_layout(auto, FieldShape(FieldMode.single))


# --------------------------------------------------------------------------- parameter counts
def _mlp(*dims):
    return sum(a * b + b for a, b in itertools.pairwise(dims))


COUNTS = [
    # (network, options, shape, trained parameters by hand)
    ("fourier", {"features": 8, "hidden": (12, 10)}, FieldShape(FieldMode.multi),
     (16 * 12 + 12) + (12 * 10 + 10) + (10 * 2 + 2)),
    ("wire", {"hidden": (6, 5)}, FieldShape(FieldMode.multi),
     (3 * 6 + 6) + 2 * (6 * 5 + 5) + 2 * (5 * 1 + 1)),
    ("finer", {"hidden": (7, 9, 4)}, FieldShape(FieldMode.single),
     (2 * 7 + 7) + (7 * 9 + 9) + (9 * 4 + 4) + (4 * 2 + 2)),
    ("hashgrid", {"levels": 3, "base_resolution": 2, "finest_resolution": 8, "hidden": (16,),
                  "log2_table_size": 8}, FieldShape(FieldMode.multi),
     (27 + 125 + 256) * 2 + (6 * 16 + 16) + (16 * 2 + 2)),
    ("hashgrid", {"levels": 2, "base_resolution": 3, "finest_resolution": 5, "hidden": (8,),
                  "encode_frequency": False, "features_per_level": 4},
     FieldShape(FieldMode.multi), (16 + 36) * 4 + (9 * 8 + 8) + (8 * 2 + 2)),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("network", "options", "shape", "expected"), COUNTS)
def test_parameter_counts_match_hand_computed_formulas(backend, network, options, shape, expected):
    _backend_module(backend)
    model = load_plugins().registry.get("model", f"{network}_{backend}").load()
    config = model.config_class(**{**options, "mode": shape.mode, "device": "cpu"})
    built = model.backend_class(NetworkBuild(model.network_factory, config, shape))
    assert built.parameters_per_network == expected
    assert sum(p.size for p in built.parameters()) == expected


def test_fourier_matrix_has_its_sigmas_and_is_not_a_parameter():
    config = FourierFieldConfig(features=4000, sigma=3.0, frequency_sigma=0.5)
    state = field_network_state(config, FieldShape(FieldMode.multi), 0, seed=1)
    b = state["features.B"]
    assert b.shape == (3, 4000)
    assert np.std(b[:2]) == pytest.approx(3.0, rel=0.03)
    assert np.std(b[2]) == pytest.approx(0.5, rel=0.05)


# --------------------------------------------------------------------------- parts: closed forms
@pytest.mark.parametrize("backend", BACKENDS)
def test_fourier_features_match_the_closed_form(backend):
    networks = _backend_module(backend)
    rng = np.random.default_rng(0)
    b = rng.normal(0, 4.0, (3, 7)).astype(np.float32)
    v = rng.uniform(-1, 1, (20, 3)).astype(np.float32)
    features = networks.FourierFeatures(3, 7)
    if backend == "torch":
        import torch

        features.B = torch.as_tensor(b)
    else:
        import equinox as eqx

        features = eqx.tree_at(lambda m: m.B.value, features, b)
    angle = 2 * np.pi * v.astype(np.float64) @ b.astype(np.float64)
    expected = np.concatenate([np.cos(angle), np.sin(angle)], axis=1)
    np.testing.assert_allclose(_call(backend, features, v), expected, atol=2e-5)


def _call_pair(backend, module, re, im):
    if backend == "torch":
        import torch

        with torch.no_grad():
            return _to_numpy(module(torch.as_tensor(re),
                                    None if im is None else torch.as_tensor(im)))
    return _to_numpy(module(re, im))


@pytest.mark.parametrize("backend", BACKENDS)
def test_gabor_wavelet_matches_its_formula_for_real_and_complex_inputs(backend):
    networks = _backend_module(backend)
    gabor = networks.Gabor(7.0, 1.5)
    rng = np.random.default_rng(1)
    re = rng.uniform(-1, 1, (5, 4)).astype(np.float32)
    im = rng.uniform(-1, 1, (5, 4)).astype(np.float32)
    for z_im in (None, im):
        z = re.astype(np.float64) + (0 if z_im is None else 1j * z_im.astype(np.float64))
        psi = np.exp(1j * 7.0 * z - np.abs(1.5 * z) ** 2)
        out = _call_pair(backend, gabor, re, z_im)                   # [Re psi, Im psi]
        np.testing.assert_allclose(out, np.concatenate([psi.real, psi.imag], axis=1),
                                   rtol=2e-5, atol=2e-6)
    # psi(0.3 + 0.2 i), by hand: exp(7i (0.3 + 0.2i) - 2.25 * 0.13) = exp(-1.6925) e^{2.1 i}
    one = _call_pair(backend, gabor, np.array([[0.3]], np.float32), np.array([[0.2]], np.float32))
    expected = math.exp(-1.6925) * complex(math.cos(2.1), math.sin(2.1))
    assert complex(*one[0]) == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_complex_linear_is_a_complex_matrix_product(backend):
    networks = _backend_module(backend)
    rng = np.random.default_rng(2)
    w = rng.normal(size=(2, 4, 3)).astype(np.float32)
    b = rng.normal(size=(2, 3)).astype(np.float32)
    z = rng.normal(size=(6, 4)) + 1j * rng.normal(size=(6, 4))
    layer = networks.ComplexLinear(4, 3)
    if backend == "torch":
        import torch

        layer.weight.data, layer.bias.data = torch.as_tensor(w), torch.as_tensor(b)
    else:
        import equinox as eqx

        layer = eqx.tree_at(lambda m: (m.weight, m.bias), layer, (w, b))
    expected = z @ (w[0] + 1j * w[1]) + (b[0] + 1j * b[1])
    out = _call(backend, layer, np.concatenate([z.real, z.imag], axis=1).astype(np.float32))
    np.testing.assert_allclose(out[:, :3] + 1j * out[:, 3:], expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_finer_activation_and_its_gradient_match_the_formula(backend):
    networks = _backend_module(backend)
    z = np.array([-1.3, -0.4, 0.0, 0.25, 0.9], np.float32)
    zz = z.astype(np.float64)
    expected = np.sin(30.0 * (np.abs(zz) + 1) * zz)
    np.testing.assert_allclose(_call(backend, networks.Finer(30.0), z), expected, atol=2e-5)
    # the factor |z| + 1 held constant: d/dz = w (|z| + 1) cos(.); through it: w (2|z| + 1) cos(.)
    cos = np.cos(30.0 * (np.abs(zz) + 1) * zz)
    for through, factor in ((False, np.abs(zz) + 1), (True, 2 * np.abs(zz) + 1)):
        act = networks.Finer(30.0, through)
        if backend == "torch":
            import torch

            t = torch.tensor(z, requires_grad=True)
            act(t).sum().backward()
            grad = t.grad.numpy()
        else:
            import jax

            grad = np.asarray(jax.grad(lambda v, a=act: a(v).sum())(z))
        np.testing.assert_allclose(grad, 30.0 * factor * cos, rtol=1e-4, atol=1e-3)


# --------------------------------------------------------------------------- hash grid
def _grid_row(vertex, n, dims, rows):
    """Row of grid vertex ``vertex`` (Python ints): row-major when the level's (n + 1)^dims
    vertices fit the table, else (x * 1 XOR y * 2654435761 XOR z * 805459861) mod rows."""
    if (n + 1) ** dims <= rows:
        return sum(v * (n + 1) ** axis for axis, v in enumerate(vertex))
    primes = (1, 2654435761, 805459861)
    h = 0
    for v, p in zip(vertex, primes, strict=False):
        h ^= v * p
    return h % rows


def brute_force_encoding(x, resolutions, tables, dims):
    """Every level's features at every point as the sum over ALL (n + 1)^dims grid vertices of
    table[row(vertex)] times the tent weight prod_axes max(0, 1 - |u n - vertex|), u = (x + 1)/2
    clamped to [0, 1]: bilinear (2-D) or trilinear (3-D) interpolation by its definition."""
    out = []
    for point in np.asarray(x, dtype=np.float64):
        u = np.clip((point[:dims] + 1) / 2, 0, 1)
        feats = []
        for n, table in zip(resolutions, tables, strict=True):
            value = np.zeros(table.shape[1])
            for vertex in itertools.product(range(n + 1), repeat=dims):
                weight = np.prod(np.maximum(0.0, 1 - np.abs(u * n - np.array(vertex))))
                if weight:
                    value += weight * table[_grid_row(vertex, n, dims, table.shape[0])]
            feats.append(value)
        out.append(np.concatenate([*feats, point[dims:]]))
    return np.array(out)


def _encoding(backend, layout, tables):
    networks = _backend_module(backend)
    encoding = networks.HashGridEncoding(layout)
    if backend == "torch":
        import torch

        for param, table in zip(encoding.tables, tables, strict=True):
            param.data = torch.as_tensor(table)
        return encoding
    import equinox as eqx

    return eqx.tree_at(lambda e: e.tables, encoding, [np.asarray(t) for t in tables])


GRID_CASES = [
    # options, mode, which levels hash: (x, y, f) with N = 2, 4, 9 and T = 64 rows;
    # (x, y) with f raw, N = 3, 6, 12; single mode (x, y), N = 5, 7, every level dense
    ({"levels": 3, "base_resolution": 2, "finest_resolution": 9, "log2_table_size": 6},
     FieldMode.multi, (False, True, True)),
    ({"levels": 3, "base_resolution": 3, "finest_resolution": 12, "log2_table_size": 6,
      "encode_frequency": False}, FieldMode.multi, (False, False, True)),
    ({"levels": 2, "base_resolution": 5, "finest_resolution": 7, "features_per_level": 3},
     FieldMode.single, (False, False)),
]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("options", "mode", "hashed"), GRID_CASES)
def test_hash_grid_matches_a_brute_force_multilinear_lookup(backend, options, mode, hashed):
    layout = hash_grid_layout(HashGridFieldConfig(**options), FieldShape(mode))
    assert layout.hashed == hashed
    rng = np.random.default_rng(3)
    tables = [rng.uniform(-1, 1, (rows, layout.features)).astype(np.float32)
              for rows in layout.table_sizes]
    dims_in = 3 if mode == FieldMode.multi else 2
    x = rng.uniform(-1, 1, (25, dims_in)).astype(np.float32)
    x[0, :2] = [-1.0, 1.0]                   # the grid's corners and a point outside it
    x[1, :2] = [1.0, -1.0]
    x[2, :2] = [1.3, 0.2]
    got = _call(backend, _encoding(backend, layout, tables), x)
    expected = brute_force_encoding(x, layout.resolutions, tables, layout.dims)
    assert got.shape == (25, layout.encoded_dim)
    np.testing.assert_allclose(got, expected, atol=2e-5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_hash_grid_encoding_is_continuous_across_cell_boundaries(backend):
    layout = hash_grid_layout(HashGridFieldConfig(levels=3, base_resolution=4,
                                                  finest_resolution=16, log2_table_size=8),
                              FieldShape(FieldMode.multi))
    rng = np.random.default_rng(4)
    tables = [rng.uniform(-1, 1, (rows, layout.features)).astype(np.float32)
              for rows in layout.table_sizes]
    encoding = _encoding(backend, layout, tables)
    # boundaries of every level along x (u = k / 16 lies on a cell edge of N = 4, 8, 16),
    # at random y, f
    k = rng.integers(1, 16, 40)
    base = np.column_stack([2 * k / 16 - 1, rng.uniform(-0.9, 0.9, (40, 2))])
    jumps = []
    for eps in (1e-2, 1e-3, 1e-4):
        left, right = base.copy(), base.copy()
        left[:, 0] -= eps
        right[:, 0] += eps
        jump = np.abs(_call(backend, encoding, right.astype(np.float32))
                      - _call(backend, encoding, left.astype(np.float32)))
        jumps.append(float(jump.max()))
    # each feature is multilinear in u = (x + 1) / 2 with table values in [-1, 1]: its slope
    # in x is at most N / 2 * 2 = N <= 16, so over [b - e, b + e] it moves at most 32 e;
    # a jump at the boundary would not shrink with e
    assert jumps[0] > 1e-3                                   # the features do change
    for eps, jump in zip((1e-2, 1e-3, 1e-4), jumps, strict=True):
        assert jump <= 32 * eps + 2e-6, (eps, jumps)
    assert jumps[2] < 0.02 * jumps[0]


# --------------------------------------------------------------------------- torch vs JAX
def _engines(network, options, mode, n_networks):
    _backend_module("torch")
    _backend_module("jax")
    registry = load_plugins().registry
    built = []
    for backend in BACKENDS:
        model = registry.get("model", f"{network}_{backend}").load()
        config = model.config_class(**{**options, "mode": mode, "device": "cpu", "seed": 5})
        shape = FieldShape(config.mode, (8, 8), 6)
        built.append(model.backend_class(NetworkBuild(model.network_factory, config, shape,
                                                     n_networks)))
    return built


SMALL = {"fourier": {"features": 16, "hidden": (12, 10), "sigma": 2.0},
         "wire": {"hidden": (10, 8)},
         "finer": {"hidden": (12, 10)},
         "hashgrid": {"levels": 3, "base_resolution": 2, "finest_resolution": 12,
                      "log2_table_size": 6, "hidden": (12,), "init_scale": 0.5}}


@pytest.mark.parametrize("mode", ["multi", "single"])
@pytest.mark.parametrize("network", NETWORKS)
def test_torch_and_jax_start_alike_and_agree_on_the_forward_pass(network, mode):
    n_networks = 3 if mode == "single" else 0
    torch_engine, jax_engine = _engines(network, SMALL[network], mode, n_networks)
    a, b = torch_engine.state(), jax_engine.state()
    assert set(a) == set(b)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    x = np.random.default_rng(6).uniform(-1, 1, (50, 3 if mode == "multi" else 2))
    out = torch_engine.forward(x.astype(np.float32))
    assert out.shape == ((3,) if n_networks else ()) + (50, 2)
    assert np.std(out) > 1e-3                        # not a trivially zero network
    np.testing.assert_allclose(out, jax_engine.forward(x.astype(np.float32)), rtol=1e-4,
                               atol=1e-5)


@pytest.mark.parametrize("network", NETWORKS)
def test_a_file_written_by_torch_predicts_the_same_in_jax(tmp_path, network):
    _backend_module("torch")
    _backend_module("jax")
    registry = load_plugins().registry
    options = {**SMALL[network], "steps": 30, "batch_size": 0, "device": "cpu"}
    model = registry.create("model", f"{network}_torch", options)
    field = fixtures.smooth_field(n=8, frequencies=np.linspace(2.0, 3.0, 5), seed=2)
    model.fit(field)
    model.save(tmp_path / "m.npz")
    other = registry.get("model", f"{network}_jax").load().load(tmp_path / "m.npz",
                                                               allow_other_backend=True)
    pts = fixtures.wall_grid(6)[..., :2]
    np.testing.assert_allclose(other.predict(pts, [2.2, 2.7]), model.predict(pts, [2.2, 2.7]),
                               rtol=1e-4, atol=1e-5 * np.abs(field.values).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_wire_outputs_complex_values_and_the_trainer_takes_them(backend):
    networks = _backend_module(backend)
    config = WireFieldConfig(hidden=(6,))
    shape = FieldShape(FieldMode.multi)
    if backend == "torch":
        net = networks.field_network(config, shape)
    else:
        import jax

        net = networks.field_network(config, shape, jax.random.key(0))
    out = _call(backend, net, np.zeros((4, 3), np.float32))
    assert np.iscomplexobj(out) and out.shape == (4,)
    model = load_plugins().registry.create("model", f"wire_{backend}",
                                           {"steps": 5, "hidden": [6], "device": "cpu"})
    model.fit(fixtures.smooth_field(n=6, frequencies=np.linspace(2.0, 3.0, 4), seed=1))
    pred = model.predict(fixtures.wall_grid(3)[..., :2], [2.5])
    assert np.iscomplexobj(pred) and pred.shape == (1, 3, 3) and np.all(np.isfinite(pred))

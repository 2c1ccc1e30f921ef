"""neural_volume_torch (and neural_volume_jax when nlosfw-jax is installed): the RSD
operator written in torch and JAX against numpy's SceneOperator, and the fitted volume
against a known sparse scene and the interp baseline."""

from __future__ import annotations

import importlib
import importlib.util

import numpy as np
import pytest

pytest.importorskip("torch")

import torch
from nlosfw_torch.backend import TorchBackend
from nlosfw_torch.neural_volume import TorchPlaneOperator, total_variation, volume_albedo

from nlosfw.capture import CaptureGeometry, CaptureKind
from nlosfw.common import ConfigError, FitError
from nlosfw.evaluation import SpatialSampling, split_field
from nlosfw.image import grid_layout
from nlosfw.model.hybrid import albedo_total_variation, plane_stack, stack_bytes
from nlosfw.model.neural import FieldMode, FieldShape, NetworkBuild
from nlosfw.model.physics import (
    OperatorOptions,
    SceneOperator,
    VoxelLattice,
    training_grid,
    validation_split,
    voxel_lattice,
)
from nlosfw.plugins import load_plugins, registered_network, registered_networks
from nlosfw.testing import fixtures, heldout_error_db
from nlosfw.transform import PhasorField

HAS_JAX = bool(importlib.util.find_spec("jax") and importlib.util.find_spec("optax")
               and importlib.util.find_spec("equinox"))
NEEDS_JAX = pytest.mark.skipif(not HAS_JAX,
                               reason="needs jax, optax and equinox (pip install nlosfw-jax)")
BACKENDS = ["torch", pytest.param("jax", marks=NEEDS_JAX)]

LASER = np.array([0.07, -0.04, 0.0])
DEVICE = np.array([-0.6, 0.1, 0.3])


def _geometry(confocal: bool) -> CaptureGeometry:
    if confocal:
        return CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=DEVICE, sensor_xyz=DEVICE)
    return CaptureGeometry(kind=CaptureKind.SINGLE_SPOT, laser_point=LASER, laser_xyz=DEVICE,
                           sensor_xyz=DEVICE)


def _operator(confocal: bool, wall_step: float, vox_step: float) -> SceneOperator:
    wall = grid_layout(fixtures.rect_wall_grid((7, 6), wall_step, center=(0.02, -0.01)))
    lattice = VoxelLattice(np.array([0.4, 0.47, 0.55]), (-0.23, -0.31), (vox_step, vox_step),
                           (9, 11))
    return SceneOperator(lattice, wall, _geometry(confocal), np.linspace(2.0, 5.0, 6),
                         OperatorOptions(dtype=np.complex64, workers=1))


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# (wall spacing, voxel spacing): equal, voxels finer than the wall, voxels coarser
SPACINGS = [(0.06, 0.06), (0.08, 0.04), (0.05, 0.1)]


@pytest.mark.parametrize("confocal", [False, True], ids=["single_spot", "confocal"])
@pytest.mark.parametrize("spacings", SPACINGS, ids=["same", "finer_voxels", "coarser_voxels"])
def test_torch_and_jax_operators_match_numpy(confocal, spacings):
    """A random albedo propagated by the torch (and JAX) operator equals numpy's
    SceneOperator.forward to 1e-5 relative (complex64 everywhere); torch and JAX agree."""
    op = _operator(confocal, *spacings)
    albedo = np.random.default_rng(3).random(op.lattice.volume_shape).astype(np.float32)
    expected = op.forward(albedo)
    stack = plane_stack(op)
    got = TorchPlaneOperator(stack)(torch.from_numpy(albedo)).numpy()
    assert got.shape == expected.shape
    assert _relative(got, expected) < 1e-5
    if HAS_JAX:
        from nlosfw_jax.neural_volume import JaxPlaneOperator

        jax_got = np.asarray(JaxPlaneOperator(stack)(albedo))
        assert _relative(jax_got, expected) < 1e-5
        assert _relative(jax_got, got) < 1e-5


@pytest.mark.parametrize("confocal", [False, True], ids=["single_spot", "confocal"])
def test_the_torch_and_jax_operators_are_differentiable(confocal):
    """The gradient of 1/2 ||A a - P||^2 by autograd (torch's, and JAX's when installed)
    equals Re(A^H (A a - P)) from numpy's adjoint (an independent implementation:
    correlation with conjugate kernels); confocal scans take the batched product on the
    CPU."""
    op = _operator(confocal, 0.08, 0.04)
    assert TorchPlaneOperator(plane_stack(op)).batched == confocal
    rng = np.random.default_rng(5)
    albedo = rng.random(op.lattice.volume_shape).astype(np.float32)
    target = (rng.normal(size=op.field_shape) + 1j * rng.normal(size=op.field_shape))
    a = torch.from_numpy(albedo).requires_grad_(True)
    residual = TorchPlaneOperator(plane_stack(op))(a) - torch.from_numpy(
        target.astype(np.complex64))
    (0.5 * torch.sum(torch.abs(residual) ** 2)).backward()
    expected = op.adjoint(op.forward(albedo) - target.astype(np.complex64)).real
    assert _relative(a.grad.numpy(), expected) < 1e-4
    if HAS_JAX:                        # JAX's gradient, through its einsum on the CPU
        import jax
        import jax.numpy as jnp
        from nlosfw_jax.neural_volume import JaxPlaneOperator

        jop = JaxPlaneOperator(plane_stack(op))
        assert jop.batched == confocal
        grad = jax.grad(lambda x: 0.5 * jnp.sum(jnp.abs(jop(x) - target.astype(np.complex64))
                                                ** 2))(jnp.asarray(albedo))
        assert _relative(np.asarray(grad), expected) < 1e-4


@pytest.mark.parametrize("fold", [True, False], ids=["folded", "per_point"])
def test_the_folded_confocal_product_matches_numpy_and_its_adjoint(fold):
    """Every 4th point of a 32 x 32 wall and the model's own lattice (33 x 33 voxels):
    the confocal spectra fold into 528 orbits of the 63 x 63 padded points. Through them
    (and per point, folding off) the torch operator equals numpy's forward (1e-5) and its
    gradient numpy's adjoint (1e-4)."""
    wall = fixtures.rect_wall_grid((32, 32), 1 / 32)[1::4, 1::4]
    kept = PhasorField(values=np.zeros((6, 8, 8), complex), frequencies=np.linspace(3, 6, 6),
                       wall_xyz=wall, geometry=_geometry(True), metadata={})
    lattice = voxel_lattice(training_grid(kept, "test"), 1 / 32, np.array([0.4, 0.5, 0.6]))
    op = SceneOperator(lattice, grid_layout(wall), kept.geometry, kept.frequencies,
                       OperatorOptions(dtype=np.complex64, workers=1))
    torch_op = TorchPlaneOperator(plane_stack(op), fold=fold)
    assert torch_op.batched
    assert (torch_op.folded is not None) == fold
    if fold:
        assert torch_op.spectra.shape == (528, 6, 3)
    rng = np.random.default_rng(7)
    albedo = rng.random(op.lattice.volume_shape).astype(np.float32)
    target = (rng.normal(size=op.field_shape) + 1j * rng.normal(size=op.field_shape))
    a = torch.from_numpy(albedo).requires_grad_(True)
    out = torch_op(a)
    assert _relative(out.detach().numpy(), op.forward(albedo)) < 1e-5
    residual = out - torch.from_numpy(target.astype(np.complex64))
    (0.5 * torch.sum(torch.abs(residual) ** 2)).backward()
    expected = op.adjoint(op.forward(albedo) - target.astype(np.complex64)).real
    assert _relative(a.grad.numpy(), expected) < 1e-4


@pytest.mark.parametrize("name", registered_networks("torch"))
def test_the_albedo_in_pieces_equals_the_whole_and_so_does_its_gradient(name):
    """Every registered torch network: the albedo computed 1000 voxels at a time (each piece
    run again in the backward pass) equals the albedo of one pass over all 4 x 23 x 31
    voxels (1e-6), and so do the gradients of a weighted sum by every parameter (1e-4 of
    the largest entry). A spy sees the pieces: forward, then once more backward."""
    network = registered_network(name, "torch")
    build = NetworkBuild(network.network_factory, network.config_class(
        seed=3, hidden=[32, 32], device="cpu", steps=10), FieldShape(FieldMode.multi, (23, 31), 4))
    engine = TorchBackend(build)
    state = {**engine.fixed, **engine.params}
    sizes: list[int] = []

    def net(x: torch.Tensor) -> torch.Tensor:
        sizes.append(x.shape[0])
        return torch.func.functional_call(engine.network, state, (x,))

    coords, gain, weights = (torch.from_numpy(a) for a in fixtures.volume_inputs((4, 23, 31)))
    results = []
    for chunk in (None, 1000):
        sizes.clear()
        albedo = volume_albedo(net, coords, gain, -3.0, chunk)
        grads = torch.autograd.grad(torch.sum(albedo * weights), list(engine.params.values()))
        results.append((albedo.detach().numpy(), [g.numpy() for g in grads], list(sizes)))
    (whole, whole_grads, whole_sizes), (pieces, piece_grads, piece_sizes) = results
    assert whole_sizes == [2852]
    assert piece_sizes[:3] == [1000, 1000, 852]               # the forward pass
    assert sorted(piece_sizes[3:]) == [852, 1000, 1000]       # each piece again, backward
    assert pieces.shape == (4, 23, 31) and np.all(pieces > 0)
    np.testing.assert_allclose(pieces, whole, rtol=1e-6, atol=1e-6 * np.abs(whole).max())
    for a, b in zip(piece_grads, whole_grads, strict=True):
        assert np.abs(a - b).max() <= 1e-4 * np.abs(b).max() + 1e-12


# ------------------------------------------------------------------ a known sparse scene
N = 32                                   # the full wall: 32 x 32 points, 1/32 m apart
STEP = 4                                 # kept: every 4th point per axis (8 x 8)
FREQUENCIES = np.linspace(3.0, 6.0, 10)
DEPTHS = [0.4, 0.6]
#: Bright voxels (row, column of the lattice) on the plane at 0.5 m; the first is brightest.
BRIGHT = [((12, 20), 1.0), ((22, 9), 0.4), ((8, 8), 0.3)]
OPTIONS = {"prior": {"depth": {"range": DEPTHS, "step": 0.05}, "lateral_step": 1 / N,
                     "workers": 1}, "device": "cpu"}


@pytest.fixture(scope="module")
def sparse_scene():
    return _sparse_scene()


def _sparse_scene():
    """(full field, kept samples, held-out mask, lattice, the bright voxel's index): three
    bright voxels on the plane at 0.5 m of the model's own lattice, propagated by numpy's
    SceneOperator to every wall point, the kept samples every 4th one per axis."""
    wall = fixtures.rect_wall_grid((N, N), 1 / N)
    geometry = _geometry(False)
    held = np.ones((N, N), bool)
    held[1::STEP, 1::STEP] = False
    kept = PhasorField(values=np.zeros((FREQUENCIES.size, N // STEP, N // STEP), complex),
                       frequencies=FREQUENCIES, wall_xyz=wall[1::STEP, 1::STEP],
                       geometry=geometry, metadata={})
    depths = np.arange(DEPTHS[0], DEPTHS[1] + 0.025, 0.05)
    lattice = voxel_lattice(training_grid(kept, "test"), 1 / N, depths)
    albedo = np.zeros(lattice.volume_shape)
    plane = int(np.argmin(np.abs(depths - 0.5)))
    for (row, col), value in BRIGHT:
        albedo[plane, row, col] = value
    op = SceneOperator(lattice, grid_layout(wall), geometry, FREQUENCIES)
    full = kept.replace(values=op.forward(albedo), wall_xyz=wall)
    train = full.select(slice(None), slice(1, None, STEP), slice(1, None, STEP))
    return full, train, held, lattice, (plane, *BRIGHT[0][0])


def _heldout_nmse_db(full: PhasorField, held: np.ndarray, predicted: np.ndarray) -> float:
    return heldout_error_db(predicted, full.values, held)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_fitted_volume_beats_interp_and_finds_the_bright_voxel(backend, sparse_scene):
    """On 8 x 8 kept points of a 32 x 32 wall (16x fewer), the fitted volume predicts the
    held-out wall points at least 10 dB better than interp (NMSE over every frequency,
    measured: interp -11.8 dB, torch and JAX -30.9 dB; rsd_prior with l1_weight 0.01
    -26.7 dB), its brightest voxel is the scene's brightest, and the loss fell ten-fold."""
    full, train, held, lattice, brightest = sparse_scene
    host = load_plugins()
    interp = host.registry.create("model", "interp", {})
    interp.fit(train)
    pts = full.wall_xyz[..., :2]
    interp_db = _heldout_nmse_db(full, held, interp.predict(pts, FREQUENCIES))
    model = host.registry.create("model", f"neural_volume_{backend}", OPTIONS)
    report = model.fit(train)
    volume_db = _heldout_nmse_db(full, held, model.predict(pts, FREQUENCIES))
    assert volume_db < interp_db - 10.0, (interp_db, volume_db)
    assert model.albedo.shape == lattice.volume_shape
    assert np.unravel_index(np.argmax(model.albedo), lattice.volume_shape) == brightest
    assert report.history[-1]["loss"] < 0.1 * report.history[0]["loss"]


def test_bad_options_are_one_line_errors_naming_the_option(sparse_scene):
    _, train, _, _, _ = sparse_scene
    model = load_plugins().registry.create("model", "neural_volume_torch",
                                           {**OPTIONS, "network": "no_such_network"})
    with pytest.raises(ConfigError, match=r"model\.network.*no_such_network.*valid: .*siren"):
        model.fit(train)
    for option, value in (("steps", 0), ("network_hidden", []), ("albedo_start", 1.5),
                          ("albedo_tv", -0.1), ("albedo_tv", float("inf")),
                          ("prior.depth.range", [0.5]), ("prior.likelihood", "poisson")):
        *groups, name = option.split(".")
        options: dict = {name: value}
        for group in reversed(groups):
            options = {group: options}
        with pytest.raises(ConfigError, match=option.replace(".", r"\.")):
            load_plugins().registry.create("model", "neural_volume_torch", options)


@pytest.fixture(scope="module")
def noisy_scene(sparse_scene):
    """The sparse scene's kept samples with complex Gaussian noise of half their RMS."""
    full, train, held, _, _ = sparse_scene
    rng = np.random.default_rng(1)
    rms = float(np.sqrt(np.mean(np.abs(train.values) ** 2)))
    noise = rng.standard_normal(train.values.shape) + 1j * rng.standard_normal(train.values.shape)
    return full, train.replace(values=train.values + 0.5 * rms * noise / np.sqrt(2)), held


def _noisy_fit(backend: str, noisy_scene, **options: object) -> tuple[object, float]:
    full, noisy, held = noisy_scene
    model = load_plugins().registry.create("model", f"neural_volume_{backend}",
                                           {**OPTIONS, "steps": 400, **options})
    report = model.fit(noisy)
    return report, _heldout_nmse_db(full, held, model.predict(full.wall_xyz[..., :2],
                                                              FREQUENCIES))


def test_validation_keeps_the_step_before_the_noise_is_fitted(noisy_scene):
    """Trained on noisy samples, the network first learns the scene, then the noise: 400 steps
    with no validation predict the noise-free held-out points at -12.6 dB; holding out a
    fifth of the kept points and keeping the step with the lowest error there gives -14.8 dB
    and stops after 69 steps (patience 30)."""
    plain, plain_db = _noisy_fit("torch", noisy_scene, validation_fraction=0.0)
    kept, kept_db = _noisy_fit("torch", noisy_scene, validation_fraction=0.2, patience=30)
    assert plain.best_val_loss is None and plain.steps == 400 and not plain.stopped_early
    assert kept.stopped_early and kept.steps < 200, kept.steps
    recorded = [h["val_loss"] for h in kept.history]
    assert kept.best_val_loss is not None and 0 < kept.best_val_loss <= min(recorded) + 1e-9
    assert kept_db < plain_db - 1.0, (plain_db, kept_db)


@NEEDS_JAX
def test_torch_and_jax_stop_at_the_same_step(noisy_scene):
    """Both backends hold out the same points (the config's seed), stop at the same step
    within a few and predict the held-out points alike (measured: both 69 steps of 400,
    validation error 0.2586 and 0.2585, held-out -14.80 and -14.92 dB)."""
    torch_report, torch_db = _noisy_fit("torch", noisy_scene, validation_fraction=0.2,
                                        patience=30)
    jax_report, jax_db = _noisy_fit("jax", noisy_scene, validation_fraction=0.2, patience=30)
    assert abs(torch_report.steps - jax_report.steps) <= 5, (torch_report.steps,
                                                             jax_report.steps)
    assert abs(torch_report.best_val_loss - jax_report.best_val_loss) < 0.01 * \
        torch_report.best_val_loss
    assert abs(torch_db - jax_db) < 0.3, (torch_db, jax_db)


@pytest.mark.parametrize("confocal", [False, True], ids=["single_spot", "confocal"])
def test_the_operator_size_is_known_before_it_is_built(confocal):
    """stack_bytes (from the operator's shapes, nothing computed) is exactly what
    plane_stack holds: 3 planes x 6 frequencies of the padded lattice's spectra, and the
    laser legs on the 9 x 11 voxels unless confocal."""
    op = _operator(confocal, 0.06, 0.06)
    stack = plane_stack(op)
    held = stack.spectra.nbytes + (0 if stack.laser is None else stack.laser.nbytes)
    assert stack_bytes(op) == held
    ly, lx = op.conv.shape
    assert held == 3 * 6 * (ly * lx + (0 if confocal else 9 * 11)) * 8       # complex64



@pytest.mark.parametrize("confocal", [False, True], ids=["single_spot", "confocal"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_the_memory_check_counts_the_copies_the_cpu_operator_holds(backend, confocal):
    """On the CPU the operator uses plane_stack's arrays in place, except a confocal scan's
    spectra, which it reorders into a copy: stack_copies (what the fit's memory check
    multiplies stack_bytes by) is 1 and 2 there, as the operator's memory shows."""
    stack = plane_stack(_operator(confocal, 0.06, 0.06))
    if backend == "torch":
        op = TorchPlaneOperator(stack)
        spectra_in_place = np.shares_memory(op.spectra.numpy(), stack.spectra)
        laser_in_place = op.laser is None or np.shares_memory(op.laser.numpy(), stack.laser)
    else:
        from nlosfw_jax.neural_volume import JaxPlaneOperator
        jop = JaxPlaneOperator(stack)
        spectra_in_place = jop.spectra.unsafe_buffer_pointer() == stack.spectra.ctypes.data
        laser_in_place = jop.laser is None or \
            jop.laser.unsafe_buffer_pointer() == stack.laser.ctypes.data
    assert spectra_in_place is not confocal and laser_in_place
    model = load_plugins().registry.create("model", f"neural_volume_{backend}", OPTIONS)
    assert model.stack_copies(confocal) == (2 if confocal else 1)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_confocal_fit_is_refused_without_room_for_both_copies(backend, sparse_scene,
                                                                 monkeypatch):
    """Room for 1.5 stacks: a confocal fit on the CPU (two copies) is refused in one line,
    before its spectra are built (counting one copy, it would go on)."""
    _, train, _, _, _ = sparse_scene
    confocal = train.replace(geometry=_geometry(True))
    sizes: list[int] = []

    def counted(op: SceneOperator) -> int:
        sizes.append(stack_bytes(op))
        return sizes[-1]

    core = "nlosfw.model.hybrid.volume"
    monkeypatch.setattr(f"{core}.stack_bytes", counted)
    monkeypatch.setattr(f"{core}.available_memory", lambda: int(1.5 * sizes[-1]))
    monkeypatch.setattr(f"{core}.plane_stack", lambda op: pytest.fail("stack built"))
    model = load_plugins().registry.create("model", f"neural_volume_{backend}", OPTIONS)
    with pytest.raises(FitError) as err:
        model.fit(confocal)
    message = str(err.value)
    assert "\n" not in message and "its operator" in message and "available" in message
    assert len(sizes) == 1 and sizes[0] > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_cpu_fit_runs_the_network_in_pieces(backend, sparse_scene, monkeypatch):
    """On the CPU both backends' training evaluates the albedo through volume_albedo in
    pieces of the module's CPU_CHUNK (the sparse scene's lattice has more voxels than
    that, so the pieces are really taken)."""
    module = importlib.import_module(f"nlosfw_{backend}.neural_volume")
    chunks: list[int | None] = []
    original = module.volume_albedo

    def spy(network, coords, gain, shift, chunk=None):
        chunks.append(chunk)
        return original(network, coords, gain, shift, chunk)

    monkeypatch.setattr(module, "volume_albedo", spy)
    _, train, _, lattice, _ = sparse_scene
    assert int(np.prod(lattice.volume_shape)) > module.CPU_CHUNK
    model = load_plugins().registry.create("model", f"neural_volume_{backend}",
                                           {**OPTIONS, "steps": 2, "patience": 0})
    model.fit(train)
    assert chunks and set(chunks) == {module.CPU_CHUNK}


@pytest.mark.parametrize("backend", BACKENDS)
def test_silent_validation_points_train_without_validation(backend, sparse_scene):
    """Dead pixels at every validation point (all zero there): no validation error to
    compare, so the training keeps its last step instead of failing."""
    _, train, _, _, _ = sparse_scene
    _, val = validation_split(train.values.shape[1:], 0.1, seed=0)
    assert val is not None
    silent = train.replace(values=np.where(val > 0, 0, train.values))
    model = load_plugins().registry.create("model", f"neural_volume_{backend}",
                                           {**OPTIONS, "steps": 20})
    report = model.fit(silent)
    assert report.best_val_loss is None and report.steps == 20
    assert np.all(np.isfinite(model.albedo)) and model.albedo.max() > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_random_scan_fits_like_a_grid(backend, sparse_scene):
    """64 random points of the 32 x 32 wall (as many as the 8 x 8 grid) are placed on the
    grid they came from: the volume predicts the held-out points at least 10 dB better than
    interp (Clough-Tocher over the scattered points; measured: interp -7.7 dB, torch and
    JAX -27.7 dB, rsd_prior with l1_weight 0.01 -26.4 dB), and its brightest voxel sits where
    the scene's brightest is."""
    full, _, _, lattice, brightest = sparse_scene
    split = split_field(full, SpatialSampling(pattern="random", step=STEP, seed=2),
                        spectral="none")
    held = ~split.spatial_mask
    host = load_plugins()
    interp = host.registry.create("model", "interp", {})
    interp.fit(split.train_field)
    pts = full.wall_xyz[..., :2]
    interp_db = _heldout_nmse_db(full, held, interp.predict(pts, FREQUENCIES))
    model = host.registry.create("model", f"neural_volume_{backend}", OPTIONS)
    model.fit(split.train_field)
    volume_db = _heldout_nmse_db(full, held, model.predict(pts, FREQUENCIES))
    assert volume_db < interp_db - 10.0, (interp_db, volume_db)
    found = model.scene.lattice.points()[np.unravel_index(np.argmax(model.albedo),
                                                          model.albedo.shape)]
    np.testing.assert_allclose(found, lattice.points()[brightest], atol=1e-9)


# ------------------------------------------------------------------ a glossy lobe
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_fitted_lobe_carries_into_the_network(backend):
    """An 8 cm patch with a k = 8 lobe (analytic simulator, confocal 16 x 16 scan, every
    other point kept): with ``lobe.fit`` rsd_prior's search finds k (7.3) and the network
    trains through the operator with it, predicting the held-out points far better than
    the Lambertian volume (measured, torch and JAX: -20.3 against -9.0 dB)."""
    from nlosfw.simulate import AnalyticSimulator, scene_from_config
    from nlosfw.testing import tiny_scene_config
    from nlosfw.transform import FFTTransform

    config = tiny_scene_config(confocal=True, resolution=16, bins=300, bin_width=0.006,
                               target=(0.03, -0.02, 0.5), patch=0.08)
    config["geometry"][0]["lobe"] = 8.0
    capture = AnalyticSimulator({}).simulate(scene_from_config(config))
    field = FFTTransform({"n_frequencies": 10, "f_min": 2.0, "f_max": 4.0}).transform(capture)
    split = split_field(field, spatial_step=2, spectral="none")
    unseen = ~split.spatial_mask
    host = load_plugins()
    prior = {"depth": {"range": [0.5, 0.5]}, "lateral_step": 1 / 32, "workers": 1}
    errors, fitted = {}, {}
    for name, lobe in (("lambertian", {}), ("fitted", {"lobe": {"fit": True}})):
        model = host.registry.create("model", f"neural_volume_{backend}",
                                     {"prior": {**prior, **lobe}, "device": "cpu", "seed": 1})
        fitted[name] = model.fit(split.train_field).fitted
        errors[name] = _heldout_nmse_db(field, unseen, model.predict(field.wall_xyz[..., :2],
                                                                     field.frequencies))
    assert fitted["fitted"]["lobe_exponent"] == pytest.approx(8.0, abs=1.0)
    assert not fitted["lambertian"]
    assert errors["fitted"] < errors["lambertian"] - 10.0, errors


def test_the_total_variation_by_hand_and_in_both_backends():
    """One plane [[0, 1, 0], [0, 2, 0]] (sum 3): |1| + |-1| + |2| + |-2| along x and |1|
    along y, 7 / 3. On a random albedo torch's and JAX's term equal numpy's (1e-6), and the
    gradient is the numerator's over the constant sum: the term sharpens, never dims."""
    plane = np.array([[[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]]])
    assert albedo_total_variation(plane) == pytest.approx(7.0 / 3.0, rel=1e-12)
    assert albedo_total_variation(np.zeros((2, 3, 4))) == 0.0
    albedo = np.random.default_rng(5).random((3, 6, 7))
    a = torch.tensor(albedo, requires_grad=True)
    value = total_variation(a)
    assert float(value.detach()) == pytest.approx(albedo_total_variation(albedo), rel=1e-6)
    value.backward()
    numerator = torch.tensor(albedo, requires_grad=True)
    (torch.abs(torch.diff(numerator, dim=2)).sum()
     + torch.abs(torch.diff(numerator, dim=1)).sum()).backward()
    np.testing.assert_allclose(a.grad.numpy(), numerator.grad.numpy() / albedo.sum(),
                               rtol=1e-12)
    if HAS_JAX:
        import jax
        from nlosfw_jax.neural_volume import total_variation as jax_total_variation

        single = albedo.astype(np.float32)
        assert float(jax_total_variation(single)) == pytest.approx(
            albedo_total_variation(albedo), rel=1e-5)
        np.testing.assert_allclose(np.asarray(jax.grad(jax_total_variation)(single)),
                                   a.grad.numpy(), rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_tv_term_flattens_the_fitted_albedo(backend, sparse_scene):
    """The same fit with ``albedo_tv`` 58 (its weight 1 on the 58 points the loss sums:
    64 kept, 6 held out; reached after 20 steps) ends with an albedo of half the total
    variation or less (measured: 0.577 without, 0.263 with, torch and JAX), and the
    brightest voxel is still the scene's."""
    _, train, _, lattice, brightest = sparse_scene
    tv = {}
    for weight in (0.0, 58.0):
        model = load_plugins().registry.create("model", f"neural_volume_{backend}",
                                               {**OPTIONS, "albedo_tv": weight})
        model.fit(train)
        tv[weight] = albedo_total_variation(model.albedo)
        assert np.unravel_index(np.argmax(model.albedo), lattice.volume_shape) == brightest
    assert tv[58.0] < 0.5 * tv[0.0], tv


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_tv_weight_is_per_training_point_and_rises_by_at_most_its_rise(backend, sparse_scene,
                                                                           monkeypatch):
    """The weight the backend trains with is ``albedo_tv`` over the points the loss sums
    (the kept ones not held out for validation: fewer points, a stronger term), rising by
    ``albedo_tv_rise`` a step up to it (0: the whole weight from the first step)."""
    _, train, _, _, _ = sparse_scene
    seen = []

    def fitted(**options):
        model = load_plugins().registry.create(
            "model", f"neural_volume_{backend}",
            {**OPTIONS, "albedo_tv": 29.0, "steps": 2, "patience": 0, **options})
        original = type(model).train

        def spy(self, problem, on_step=None):
            seen.append(problem)
            return original(self, problem, on_step)

        monkeypatch.setattr(type(model), "train", spy)
        model.fit(train)
        return seen[-1]

    problem = fitted(albedo_tv_rise=0.125)
    assert int(np.sum(problem.train)) == 64 - int(np.sum(problem.validation)) == 58
    assert problem.tv_weight == pytest.approx(29.0 / 58)
    assert [problem.tv_weight_at(k) for k in range(6)] == pytest.approx(
        [0.125, 0.25, 0.375, 0.5, 0.5, 0.5])
    assert fitted(albedo_tv_rise=0.0).tv_weight_at(0) == pytest.approx(0.5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_average_steps_keeps_the_mean_of_the_steps_up_to_the_best(backend, noisy_scene,
                                                                  monkeypatch):
    """With ``average_steps`` 5 the fitted albedo is the mean of the 5 albedos the training
    offered up to the step of lowest validation error (every offer recorded here); with 1,
    that step's alone, the same network and steps."""
    from nlosfw.model.hybrid import BestStep

    _, noisy, _ = noisy_scene
    offers: list[tuple[int, float | None, np.ndarray]] = []
    original = BestStep.offer

    def record(self, step, error, albedo):
        values = albedo.cpu().numpy() if isinstance(albedo, torch.Tensor) else albedo
        offers.append((step, error, np.asarray(values, dtype=np.float64)))
        original(self, step, error, albedo)

    monkeypatch.setattr(BestStep, "offer", record)
    fitted = {}
    for window in (1, 5):
        offers.clear()
        model = load_plugins().registry.create(
            "model", f"neural_volume_{backend}",
            {**OPTIONS, "steps": 60, "validation_fraction": 0.2, "patience": 0,
             "average_steps": window})
        model.fit(noisy)
        errors = [e for _, e, _ in offers]
        best = int(np.argmin(errors))
        assert 5 <= best < len(offers) - 1, best                # a best inside the run
        expected = np.mean([a for _, _, a in offers[best - window + 1:best + 1]], axis=0)
        np.testing.assert_allclose(model.albedo, expected.reshape(model.albedo.shape),
                                   rtol=1e-5, atol=1e-7 * float(np.max(expected)))
        fitted[window] = model.albedo
    assert not np.allclose(fitted[1], fitted[5])

"""``rsd_prior``'s exact Poisson likelihood of the photon counts (``likelihood:
poisson_counts``, :mod:`nlosfw.model.physics.counts`): a time-domain forward model of the
whole spectrum, fitted by EM on the counts of every time bin."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.cli import main
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.evaluation.splits import scattered_field, split_field
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.model.physics.counts import (
    CountsScene,
    counts_operator,
    fit_counts,
    log_likelihood,
    stopping_iteration,
)
from nlosfw.model.physics.operator import OperatorOptions, VoxelLattice
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.model.physics.response import SystemResponse
from nlosfw.testing import fixtures
from nlosfw.transform.counts import bin_counts
from nlosfw.transform.field import PhasorField, PhotonCounts
from nlosfw.transform.temporal_dft import unit_phasor
from tests.model.physics.test_prior import _geometry

DELTA_T = 0.002          # m of path per bin
N_BINS = 1800     # 3.6 m of path: the device legs' too


def _scene(confocal: bool = True, legs: bool = False, response: SystemResponse | None = None
           ) -> tuple[CountsScene, np.ndarray, np.ndarray]:
    """A lattice of 3 planes under an 8 x 8 wall, a sparse random albedo on it and the wall
    points (x, y on the lattice's grid, so the FFT operator predicts there)."""
    lattice = VoxelLattice(np.array([0.45, 0.5, 0.56]), (-0.21, -0.21), (0.06, 0.06), (8, 8))
    rng = np.random.default_rng(1)
    albedo = np.where(rng.random(lattice.volume_shape) < 0.1,
                      rng.uniform(0.5, 2.0, lattice.volume_shape), 0.0)
    wall = fixtures.rect_wall_grid((8, 8), 0.06)
    return (CountsScene(lattice, _geometry(confocal, legs), OperatorOptions(workers=1), response,
                        scale=3.0), albedo, wall)


def _counts(n: np.ndarray, count_scale: float = 1.0) -> PhotonCounts:
    return PhotonCounts(n, t_start=0.05, delta_t=DELTA_T, count_scale=count_scale)


def _expected(scene: CountsScene, albedo: np.ndarray, wall: np.ndarray, counts: PhotonCounts
              ) -> np.ndarray:
    """lambda (T, 8, 8) of the time-domain model at the capture's own bins."""
    problem = bin_counts(counts, wall, DELTA_T)
    support = np.flatnonzero(albedo.ravel() > 0)
    photons = scene.scale * counts.count_scale / counts.delta_t
    op = counts_operator(problem, scene, support, photons)
    return (op @ albedo.ravel()[support]).reshape(problem.counts.shape[0], *wall.shape[:2])


@pytest.mark.parametrize("confocal, legs", [(True, False), (False, False), (True, True)])
def test_the_counts_model_is_the_phasor_model_through_the_temporal_dft(confocal, legs):
    """The temporal DFT of the expected counts (over the count scale) is the FFT scene
    operator's field times the response's gains, with the device legs' phase when the
    times include them: two implementations of one forward model, in time and in frequency
    (measured: agree to 1.2e-4 in all three; the bins' box blurs by sinc(f delta_t))."""
    response = SystemResponse(sigma=0.012, tau=0.007, gaussian=True, offset=True)
    scene, albedo, wall = _scene(confocal, legs, response)
    ones = np.zeros((N_BINS, 8, 8))
    ones[0] = 1.0                                          # counts from the first bin on
    counts = _counts(ones, count_scale=5.0)
    lam = _expected(scene, albedo, wall, counts)
    t = counts.t_start + (np.arange(N_BINS) + 0.5) * DELTA_T
    f = np.linspace(2.0, 6.0, 9)
    spectrum = np.einsum("ft,tyx->fyx", unit_phasor(-np.outer(f, t)), lam) * DELTA_T / 5.0
    model = RSDPriorFieldModel.from_albedo(RSDPriorConfig(workers=1), scene.lattice, albedo,
                                           scene.geometry, scene.scale)
    # predict puts the device legs' phase back when the times include them
    phasor = model.predict(wall[..., :2], f) * response.gains(f)[:, None, None]
    err = np.linalg.norm(spectrum - phasor) / np.linalg.norm(phasor)
    assert err < 2e-3


def test_em_never_lowers_the_likelihood_and_recovers_a_known_background():
    """Counts drawn from the model with a known albedo and a background of 0.4 photons per
    bin; EM from an albedo off by up to 3x on the right support. Measured: the background
    0.403, the albedo's error 5 % (from 83 %)."""
    scene, albedo, wall = _scene()
    first = np.zeros((N_BINS, 8, 8))
    first[0] = 1.0
    lam = _expected(scene, albedo, wall, _counts(first))
    scale = 60.0 / lam.max()                         # about 60 photons at the brightest bin
    rng = np.random.default_rng(7)
    n = rng.poisson(scale * lam + 0.4).astype(float)
    counts = _counts(n)
    problem = bin_counts(counts, wall, 4 * DELTA_T)
    assert problem.factor == 4 and problem.counts.sum() == n.sum()
    support = np.flatnonzero(albedo.ravel() > 0)
    op = counts_operator(problem, scene, support, scene.scale / DELTA_T)
    truth = scale * albedo.ravel()[support]
    start = truth * rng.uniform(1 / 3, 3, truth.size)
    a, b, history = fit_counts(problem.counts, op, start, 300)
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history[:-1]))
    assert history[-1] > history[0]
    expected = (op @ a).reshape(problem.counts.shape) + b[:, None]
    assert expected.sum() == pytest.approx(problem.counts.sum(), rel=1e-6)   # EM's balance
    assert b.mean() / 4 == pytest.approx(0.4, rel=0.05)
    before = np.linalg.norm(start - truth) / np.linalg.norm(truth)
    after = np.linalg.norm(a - truth) / np.linalg.norm(truth)
    assert before > 0.5 and after < 0.1
    truth_expected = (op @ truth).reshape(problem.counts.shape) + 0.4 * 4
    assert history[-1] >= log_likelihood(problem.counts, truth_expected) - 1.0


@pytest.mark.parametrize("seed", [7, 8])
def test_stopping_where_a_held_out_half_of_the_counts_peaks_does_not_fit_the_noise(seed):
    """Few counts (3 photons at the brightest bin) and every voxel free, from a flat start:
    EM run for 500 iterations fits the noise; stopped by the other half's likelihood it
    does not. Measured (seeds 7, 8): stops after 7 and 7 iterations; error of the expected
    counts against the noise-free ones 0.63 and 0.61, against 1.52 and 1.30 after 500."""
    scene, albedo, wall = _scene()
    first = np.zeros((N_BINS, 8, 8))
    first[0] = 1.0
    lam = _expected(scene, albedo, wall, _counts(first))
    scale = 3.0 / lam.max()
    n = np.random.default_rng(seed).poisson(scale * lam + 0.4).astype(float)
    problem = bin_counts(_counts(n), wall, 4 * DELTA_T)
    everything = np.arange(albedo.size)
    op = counts_operator(problem, scene, everything, scene.scale / DELTA_T)
    truth = (op @ (scale * albedo.ravel())).reshape(problem.counts.shape)
    start = np.full(albedo.size, scale * albedo.mean())
    steps = stopping_iteration(problem, op, start, 500, seed=0)
    assert 2 <= steps <= 50

    def error(iterations: int) -> float:
        a = fit_counts(problem.counts, op, start, iterations)[0]
        return float(np.linalg.norm((op @ a).reshape(truth.shape) - truth)
                     / np.linalg.norm(truth))

    assert error(steps) < 0.75 * error(500)


def test_binned_counts_start_at_the_first_count_and_sum_whole_bins():
    n = np.zeros((20, 1, 2))
    n[5:, :, :] = 1.0
    n[7, 0, 1] = 4.0
    problem = bin_counts(_counts(n), np.zeros((1, 2, 3)), 3.5 * DELTA_T)
    assert problem.factor == 3 and problem.counts.shape == (5, 2)
    np.testing.assert_array_equal(problem.counts[0], [3.0, 6.0])
    np.testing.assert_allclose(problem.edges[0], 0.05 + 5 * DELTA_T)
    np.testing.assert_allclose(np.diff(problem.edges), 3 * DELTA_T)
    # 3 photons in the first bin are one in each of its capture bins, through the DFT
    f = np.array([2.0, 5.0])
    t = 0.05 + (np.arange(5, 8) + 0.5) * DELTA_T
    direct = (np.exp(-2j * np.pi * np.outer(f, t)).sum(axis=1)) * DELTA_T
    np.testing.assert_allclose(problem.field_of(np.array([3.0, 0, 0, 0, 0]), f), direct)


def test_a_field_carries_its_counts_through_selection_and_scattering_but_not_held_frequencies():
    rng = np.random.default_rng(0)
    wall = fixtures.rect_wall_grid((4, 5), 0.1)
    n = rng.poisson(2.0, (30, 4, 5)).astype(float)
    field = PhasorField(rng.normal(size=(12, 4, 5)) + 0j, np.linspace(2, 3, 12), wall,
                        _geometry(True), counts=_counts(n))
    sub = field.select([0, 2], slice(None, None, 2), slice(1, None, 2))
    assert sub.counts is not None
    np.testing.assert_array_equal(sub.counts.counts, n[:, ::2, 1::2])
    mask = rng.random((4, 5)) < 0.5
    scattered = scattered_field(field, mask)
    assert scattered.counts is not None
    np.testing.assert_array_equal(scattered.counts.counts, n[:, mask][:, None, :])
    assert split_field(field, 2, spectral="none").train_field.counts is not None
    assert split_field(field, 2, spectral="interleaved").train_field.counts is None
    for bad in (n[:, :2], -n):
        with pytest.raises(DataError, match="counts"):
            field.replace(counts=_counts(bad))


# ---------------------------------------------------------------- in a run
def _run(tmp_path, monkeypatch, *overrides: str, model: str = "rsd_prior"
         ) -> tuple[int, dict]:
    """A run of the tiny scene with photon noise and known dark counts (256 per wall point
    over the 512 bins: 0.5 a bin) fitted with poisson_counts: (status, fit report). An
    override ``prior.<option>`` sets rsd_prior's option (``model.prior.`` of a hybrid)."""
    prior = "model." if model == "rsd_prior" else "model.prior."
    overrides = tuple(prior + o.removeprefix("prior.") if o.startswith("prior.") else o
                      for o in overrides)
    reports: list = []
    fit = RSDPriorFieldModel.fit

    def recording(self, field, *args, **kwargs):
        reports.append(fit(self, field, *args, **kwargs))
        return reports[-1]

    monkeypatch.setattr(RSDPriorFieldModel, "fit", recording)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    status = main(["scene=tiny", "scene.noise.model=poisson", "scene.noise.photons=1e6",
                   "scene.noise.dark_counts=256", f"model={model}",
                   f"{prior}likelihood=poisson_counts", f"{prior}iterations=60",
                   "split.spatial_step=2", "transform.n_frequencies=21",
                   "reconstruction.n_depths=4", "figures.enabled=false", *overrides,
                   f"hydra.run.dir={tmp_path / 'run'}"])
    return status, (reports[0].fitted if reports else {})


@pytest.mark.parametrize("count_splitting, model", [([], "rsd_prior"),
                                             (["split.count_splitting=true"], "rsd_prior"),
                                             ([], "rsd_residual_torch")])
def test_a_run_recovers_the_simulators_dark_counts(tmp_path, monkeypatch, count_splitting,
                                                   model):
    """The background per bin the counts' EM finds is the simulator's dark-count floor
    (0.5 photons a bin; half of it in half A with count splitting); the neural residual's
    physics stage takes the counts too. Measured: 0.510 and 0.250."""
    extra = [] if model == "rsd_prior" else ["model.network_steps=20"]
    if extra:
        pytest.importorskip("torch")
    status, fitted = _run(tmp_path, monkeypatch, "split.spectral=none",
                          "prior.counts.stop=likelihood", *count_splitting, *extra, model=model)
    assert status == 0
    floor = 0.25 if count_splitting else 0.5
    assert fitted["counts_background"] == pytest.approx(floor, rel=0.1)
    assert fitted["counts_loglik_gain"] > 0 and fitted["counts_support_voxels"] > 0
    if model != "rsd_prior":
        return
    # the model file keeps the background's phasor, which a least-squares fit has none of
    model = RSDPriorFieldModel.load(tmp_path / "run" / "field_model.npz")
    assert model.background is not None and model.config.background == "none"
    assert np.all(np.abs(model.background.values) > 0)


def test_held_out_frequencies_are_refused_before_the_run(tmp_path, monkeypatch, capsys):
    status, fitted = _run(tmp_path, monkeypatch)               # spectral: interleaved
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and not fitted
    assert err.startswith("error: split.spectral: ") and "split.spectral=none" in err
    assert not (tmp_path / "run" / "metrics.json").exists()


def test_a_field_without_counts_is_refused_in_one_line():
    rng = np.random.default_rng(0)
    field = PhasorField(rng.normal(size=(4, 4, 4)) + 0j, np.linspace(2, 3, 4),
                        fixtures.rect_wall_grid((4, 4), 0.1), _geometry(True))
    model = RSDPriorFieldModel({"likelihood": "poisson_counts", "depth": {"range": [0.5, 0.5]},
                                "iterations": 5, "workers": 1})
    with pytest.raises(ConfigError, match="model.likelihood") as err:
        model.fit(field)
    assert "\n" not in str(err.value) and "split.spectral=none" in str(err.value)


def test_device_legs_in_the_times_need_a_field_that_keeps_them(tmp_path, monkeypatch, capsys):
    """The counts' model writes the device legs into each point's times; a transform that
    takes them out of the field is refused in one line, and one that keeps them fits (the
    simulator's dark counts found again)."""
    legs = ["scene.capture.device_legs=true", "split.spectral=none",
            "model.counts.stop=likelihood"]
    status, fitted = _run(tmp_path, monkeypatch, *legs)
    err = capsys.readouterr().err
    assert status == 2 and not fitted and err.count("\n") == 1
    assert err.startswith("error: transform.remove_device_legs: ")
    (tmp_path / "kept").mkdir()
    status, fitted = _run(tmp_path / "kept", monkeypatch, *legs,
                          "transform.remove_device_legs=false")
    assert status == 0
    assert fitted["counts_background"] == pytest.approx(0.5, rel=0.1)
    # a capture file with the legs in its times: refused before the run
    capture = tmp_path / "kept" / "run" / "capture.hdf5"
    status = main([f"capture.path={capture}", "model=rsd_prior", "split.spectral=none",
                   "model.likelihood=poisson_counts", f"hydra.run.dir={tmp_path / 'file'}"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and str(capture) in err
    assert err.startswith("error: transform.remove_device_legs: ")
    assert not (tmp_path / "file").exists()

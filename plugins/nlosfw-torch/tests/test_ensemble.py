"""ensemble_torch: rsd_prior, the residual and the neural volume weighed by their error at
held-out kept wall points, decided from the training field alone."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from nlosfw.common import ConfigError, PlanShape
from nlosfw.model.hybrid import held_out_points
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures, heldout_error_db

N = 12                                   # 12 x 12 wall points, 1/12 m apart
FREQUENCIES = np.linspace(2.0, 4.0, 8)
PRIOR = {"iterations": 60, "amplitude": "point", "l1_weight": 0.001, "workers": 1,
         "depth": {"range": [0.3, 0.7]}}
RESIDUAL = {"network_steps": 200, "network_lr": 2e-3, "network_batch_size": 0,
            "network_validation_fraction": 0.0, "network_hidden": [16, 16],
            "residual_weight": 0.1}
VOLUME = {"prior": {"amplitude": "point", "depth": {"range": [0.3, 0.7], "step": 0.05},
                    "workers": 1},
          "network_hidden": [16, 16], "steps": 150, "validation_fraction": 0.1}
OPTIONS = {"prior": PRIOR, "residual": RESIDUAL, "volume": VOLUME, "tv_weights": [0.0, 0.1]}


def _scene(offset: float, seed: int = 0):
    """(full field, kept samples, held-out mask): a point scatterer's exact field plus a
    smooth complex offset the same at every frequency (no scene in 0.3-0.7 m makes it),
    ``offset`` times the scatterer's RMS, and complex noise of a tenth of it; every other
    sample in x and y is kept."""
    field = fixtures.point_field((0.1, -0.05, 0.5), (N, N), 1 / N, FREQUENCIES)
    x, y = field.wall_xyz[..., 0], field.wall_xyz[..., 1]
    rms = float(np.sqrt(np.mean(np.abs(field.values) ** 2)))
    term = offset * rms * (1 + 0.8 * x - 0.6 * y) * np.exp(0.5j)
    rng = np.random.default_rng(seed)
    noise = 0.1 * rms * (rng.standard_normal(field.values.shape)
                         + 1j * rng.standard_normal(field.values.shape)) / np.sqrt(2)
    full = field.replace(values=(field.values + term[None] + noise).astype(np.complex128))
    held = np.ones((N, N), bool)
    held[::2, ::2] = False
    return full, full.select(slice(None), slice(0, None, 2), slice(0, None, 2)), held


def _model(name: str, **options):
    return load_plugins().registry.create("model", name, {"device": "cpu", **options})


def _ensemble(**options):
    return _model("ensemble_torch", **{**OPTIONS, **options})


def _points(field):
    return field.wall_xyz[..., :2]


@pytest.fixture(scope="module")
def offset_scene():
    return _scene(0.5)


@pytest.fixture(scope="module")
def plain_scene():
    return _scene(0.0)


def test_a_clear_winner_is_reproduced_exactly(plain_scene):
    """rsd_prior members told to look for the scene 1.5-2 m away cannot fit a scatterer at
    0.5 m; the neural volume can. Its weight is then exactly 1, and the ensemble predicts
    exactly what neural_volume_torch fitted alone with its options (the group ``volume``
    over the ensemble's defaults) predicts (the same seed: it holds out the ensemble's own
    validation points)."""
    full, train, _ = plain_scene
    far = {**PRIOR, "depth": {"range": [1.5, 2.0]}}
    # a point scatterer: no flat target for the volume's TV term (the ensemble's default)
    model = _ensemble(prior=far, add_residual=False, volume={**VOLUME, "albedo_tv": 0.0})
    report = model.fit(train)
    assert model.member_weights == {"neural_volume": 1.0, "rsd_prior_tv0": 0.0,
                                    "rsd_prior_tv0.1": 0.0}, report.fitted
    assert report.fitted["validation_db_neural_volume"] < \
        report.fitted["validation_db_rsd_prior_tv0"] - 6.0, report.fitted
    alone = load_plugins().registry.create("model", "neural_volume_torch",
                                           model.config.volume_config())
    assert alone.config.prior.fit_frequencies == 64
    alone_report = alone.fit(train)
    assert report.fitted["steps_neural_volume"] == alone_report.steps, report.fitted
    assert np.array_equal(model.predict(_points(full), FREQUENCIES),
                          alone.predict(_points(full), FREQUENCIES))


def test_one_member_alone_is_that_model_fitted_on_every_kept_point(plain_scene):
    """With one member and no residual nothing is held out: the ensemble is rsd_prior
    (its TV weight) fitted alone, exactly."""
    full, train, _ = plain_scene
    model = _ensemble(tv_weights=[0.1], neural_volume=False, add_residual=False)
    model.fit(train)
    alone = _model("rsd_prior", **PRIOR, tv_weight=0.1)
    alone.fit(train)
    assert model.member_weights == {"rsd_prior_tv0.1": 1.0}
    assert np.array_equal(model.predict(_points(full), FREQUENCIES),
                          alone.predict(_points(full), FREQUENCIES))


def test_the_training_field_alone_decides(offset_scene):
    """Values outside the kept points (half B's, in a study) cannot change the choice: two
    fields equal at the kept points give the same weights and fields. The values at the
    held-out kept points decide it: replaced by the TV member's own field there, its weight
    rises."""
    full, train, held = offset_scene
    options = {"neural_volume": False, "add_residual": False}
    first = _ensemble(**options)
    first.fit(train)
    other_b = full.replace(values=np.where(held[None], 3.0 * full.values, full.values))
    again = _ensemble(**options)
    again.fit(other_b.select(slice(None), slice(0, None, 2), slice(0, None, 2)))
    assert first.member_weights == again.member_weights
    assert np.array_equal(first.predict(_points(full), FREQUENCIES),
                          again.predict(_points(full), FREQUENCIES))
    points = held_out_points(train, 0.1, 0, "test").validation
    tv = _model("rsd_prior", **PRIOR, tv_weight=0.1)
    tv.fit(train.replace(values=np.where(points[None], 0, train.values)))
    shifted = train.replace(values=np.where(
        points[None], tv.predict(_points(train), FREQUENCIES), train.values))
    moved = _ensemble(**options)
    report = moved.fit(shifted)
    assert moved.member_weights["rsd_prior_tv0.1"] > \
        first.member_weights["rsd_prior_tv0.1"] + 0.3, (first.member_weights, report.fitted)


def test_the_residual_adds_what_no_scene_makes(offset_scene):
    """A zero-delay offset on a point scatterer's field: the physical members cannot make
    it; the residual on their blend does (its scale 1), and the ensemble's held-out error
    (the 75 % of wall points not kept, every frequency) is at least 6 dB below every
    physical model fitted alone, and within 1.5 dB of rsd_residual_torch's, whose two
    stages see all 36 kept points where the ensemble weighs on 4 of them (measured:
    ensemble -14.6 dB, rsd_prior -6.9, neural_volume_torch -6.4, rsd_residual_torch
    -15.7)."""
    full, train, held = offset_scene
    model = _ensemble()
    report = model.fit(train)
    ensemble_db = heldout_error_db(model.predict(_points(full), FREQUENCIES), full.values,
                                   held)
    scores = {}
    for name, options in (("rsd_prior", PRIOR), ("neural_volume_torch", VOLUME),
                          ("rsd_residual_torch", {**RESIDUAL, "prior": PRIOR})):
        member = _model(name, **options)
        member.fit(train)
        scores[name] = heldout_error_db(member.predict(_points(full), FREQUENCIES),
                                        full.values, held)
    assert model.residual_scale > 0.5, report.fitted
    assert ensemble_db < min(scores["rsd_prior"], scores["neural_volume_torch"]) - 6.0, \
        (ensemble_db, scores)
    assert ensemble_db < scores["rsd_residual_torch"] + 1.5, (ensemble_db, scores)


def test_save_and_load_keep_the_members_and_the_residual(offset_scene, tmp_path):
    full, train, _ = offset_scene
    model = _ensemble()
    model.fit(train)
    model.save(tmp_path / "m")
    loaded = type(model).load(tmp_path / "m")
    assert loaded.member_weights == model.member_weights
    assert loaded.residual_scale == model.residual_scale > 0
    assert np.array_equal(loaded.predict(_points(full), FREQUENCIES),
                          model.predict(_points(full), FREQUENCIES))


def test_bad_options_name_the_group():
    with pytest.raises(ConfigError, match=r"model\.tv_weights"):
        _model("ensemble_torch", tv_weights=[0.1, 0.1])
    model = _model("ensemble_torch", residual={"network": "no_such_network"})
    with pytest.raises(ConfigError, match=r"model\.residual\.network"):
        type(model).check_config(model.config)
    with pytest.raises(ConfigError, match=r"model\.volume\.steps"):
        _model("ensemble_torch", volume={"steps": 0})


def test_the_memory_estimate_is_the_members_together():
    """The plan's memory estimate of the ensemble: the neural volume's, each rsd_prior
    member's and the residual network's estimates (each part naming its member, the torch
    runtime they share counted once), and the members' fields that weigh them; a lone
    neural volume without a residual is exactly neural_volume_torch's estimate."""
    registry = load_plugins().registry
    shape = PlanShape(bins=2048, sensors=4096, grid=(64, 64), spacing=1 / 64, confocal=True,
                      frequencies=151, f_min=4.0, f_max=16.0, training_frequencies=135,
                      training=(16, 16), step=4, depth_range=(0.3, 0.9), deepest=1.5)
    model = _ensemble(tv_weights=[0.03, 0.1])
    estimate = type(model).estimate_memory(model.config, shape)
    volume = registry.get("model", "neural_volume_torch").load().estimate_memory(
        model.config.volume_config(), shape)
    residual = registry.get("model", "rsd_residual_torch").load().estimate_memory(
        model.config.residual_config(), shape)
    assert volume.total > 0 and residual.total > 0
    fields = 16.0 * (3 + 2) * shape.training_frequencies * 64 * 64   # 3 members, blend, residual
    assert estimate.total == pytest.approx((volume + residual).total + fields)
    runtimes = [p for p in estimate.merged() if p.what == "the model's runtime"]
    assert len(runtimes) == 1 and runtimes[0].once == "runtime:torch"
    whys = [p.why for p in estimate.parts if not p.once and p.what != "the members' fields"]
    assert {w.split(":")[0] for w in whys} == {"member neural_volume", "member residual"}
    alone = _ensemble(tv_weights=[], add_residual=False)
    assert type(alone).estimate_memory(alone.config, shape).total == volume.total


def test_the_plan_reads_the_members_needs():
    """The rsd_prior members' Poisson likelihood is the ensemble's need: the plan of a
    run asks the scene for photon counts and computes the field's variance."""
    from tests.planned import TINY, planned

    plain = planned((*TINY[:-1], "model=ensemble_torch", "model.device=cpu"))
    assert not plain.needs.noise_variance and not plain.needs.photon_counts
    with pytest.raises(ConfigError, match="a Poisson likelihood needs photon counts"):
        planned((*TINY[:-1], "model=ensemble_torch", "model.prior.likelihood=poisson"))
    poisson = planned((*TINY[:-1], "model=ensemble_torch", "model.prior.likelihood=poisson",
                       "scene.noise.model=poisson"))
    assert poisson.needs.noise_variance and not poisson.needs.photon_counts
    no_prior = planned((*TINY[:-1], "model=ensemble_torch", "model.prior.likelihood=poisson",
                        "model.tv_weights=[]", "scene.noise.model=poisson"))
    assert not no_prior.needs.noise_variance


def test_the_volume_beside_the_priors_fits_the_same_ensemble(offset_scene):
    """The volume fitted in a second thread while the rsd_prior members fit in this one
    gives the ensemble of the fits one after another, bit for bit, and its steps reach
    ``on_step`` in this thread, in order."""
    import threading

    full, train, _ = offset_scene
    seen: list[tuple[int, str]] = []
    together = _ensemble(concurrent=True)
    report = together.fit(train, on_step=lambda s: seen.append(
        (s.step, threading.current_thread().name)))
    apart = _ensemble(concurrent=False)
    apart_report = apart.fit(train)
    assert together.member_weights == apart.member_weights
    assert report.fitted == apart_report.fitted
    assert np.array_equal(together.predict(_points(full), FREQUENCIES),
                          apart.predict(_points(full), FREQUENCIES))
    names = {name for _, name in seen}
    assert names == {threading.current_thread().name}, names
    assert seen and seen[0][0] == 1                  # the volume's first step, passed on


def test_an_error_in_the_fitting_thread_stops_the_volume(plain_scene, monkeypatch):
    """If this thread stops (here a prior member's fit raises), the volume's fit stops at
    its next step instead of running on: the error is raised once the volume has ended."""
    import threading
    import time

    from nlosfw.model.physics import RSDPriorFieldModel

    _, train, _ = plain_scene
    started = time.perf_counter()

    def broken(self, *args, **kwargs):
        time.sleep(0.5)                        # the volume is training by now
        raise RuntimeError("a prior member broke")

    monkeypatch.setattr(RSDPriorFieldModel, "fit", broken)
    model = _ensemble(volume={**VOLUME, "steps": 100000, "patience": 100000})
    with pytest.raises(RuntimeError, match="a prior member broke"):
        model.fit(train)
    assert time.perf_counter() - started < 60      # 100000 steps would take many minutes
    assert not any(t.name == "nlosfw-neural-volume" for t in threading.enumerate())


def test_the_priors_beside_the_volume_take_the_cores_it_leaves():
    """Every core but the volume's thread, at most prior.workers's, at least one."""
    from nlosfw.common import available_cores
    from nlosfw.model.hybrid import EnsembleConfig
    from nlosfw.model.physics import PriorOptions

    cores = available_cores()
    assert EnsembleConfig().workers_beside_volume == max(1, cores - 1)
    assert EnsembleConfig(prior=PriorOptions(workers=1)).workers_beside_volume == 1


def test_the_volume_takes_the_priors_cores_once_they_end(plain_scene, monkeypatch):
    """Once the rsd_prior members end (here at once: each fails and is left out), the
    volume's next step runs on its own thread and the cores they used, at most every
    core; torch's setting in this thread is untouched."""
    import threading

    import torch
    from nlosfw_torch.neural_volume import NeuralVolumeTorch

    from nlosfw.common import FitError, available_cores
    from nlosfw.model.physics import RSDPriorFieldModel

    _, train, _ = plain_scene
    calls: list[tuple[int, str, int]] = []
    use_threads = NeuralVolumeTorch.use_threads

    def recorded(cls, threads):
        use_threads(threads)
        calls.append((threads, threading.current_thread().name, torch.get_num_threads()))

    def failed(self, *args, **kwargs):
        raise FitError("this member cannot fit")

    monkeypatch.setattr(NeuralVolumeTorch, "use_threads", classmethod(recorded))
    monkeypatch.setattr(RSDPriorFieldModel, "fit", failed)
    before = torch.get_num_threads()
    model = _ensemble(add_residual=False, volume={**VOLUME, "threads": 1})
    model.fit(train)
    assert model.member_weights["neural_volume"] == 1.0
    wide = min(available_cores(), 1 + model.config.workers_beside_volume)
    assert calls == [(wide, "nlosfw-neural-volume", wide)]
    assert torch.get_num_threads() == before

"""Conformance checks for every field-model plugin (see :mod:`nlosfw.testing.checks_common`).

Each check fits the plugin with its registered ``test_config`` (a small step
budget) on fields computed in closed form (:func:`~nlosfw.testing.fixtures.smooth_field`,
a sum of plane waves) and asserts numbers against that closed form, never
against the plugin's own output. A model declaring ``physical_prior`` represents only
fields a hidden scene can produce, which a sum of plane waves is not: its checks use
the exact field of a point scatterer instead (:func:`~nlosfw.testing.fixtures.point_field`),
held out at the same frequency.

Fit tolerances are chosen per model family (``family`` attribute of the model
class, or its registered name); a third-party model may declare a class
attribute ``conformance_tolerance`` (capped at :data:`MAX_TOLERANCE`).

Checks run in the frequency modes the model declares: ``multi_frequency`` (fitted
on many frequencies, asked for others) and ``single_frequency`` (fitted on one);
``save_load`` and ``neural`` add their own checks. Checks that need a fitted model but not
a good fit (save and load, errors, the parameter count) fit it for two steps when its
config has ``steps``.
"""

from __future__ import annotations

import dataclasses
import tempfile
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.evaluation import error_metrics, split_field
from nlosfw.model.interface import FieldModel, FieldModelConfig
from nlosfw.model.model_files import write_model_file
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import fixtures
from nlosfw.testing.checks_common import one_line_error
from nlosfw.testing.selection import FREQUENCY_MODES, requires
from nlosfw.transform.field import PhasorField

#: Relative L2 error (on every sample of the fixture field, held-out frequencies
#: included) that a model of each family must reach with its ``test_config``.
FIT_TOLERANCE = {"interp": 0.02, "siren": 0.08, "pe": 0.15, "tanh": 0.15, "rsd_prior": 0.05}
#: Seeds of check_fits_smooth_field (its score is the median over them).
FIT_SEEDS = (0, 1, 2)
#: Tolerance of families not listed above.
DEFAULT_TOLERANCE = 0.2
#: The largest tolerance a plugin may declare for itself.
MAX_TOLERANCE = 0.3


#: The point scatterer of the fixture of ``physical_prior`` models (m).
PHYSICAL_TARGET = (0.1, -0.05, 0.5)


def fit_fixture(single: bool = False, physical: bool = False) -> PhasorField:
    """The field the fit check learns: 12 x 12 wall points on a 1 m wall, 10 frequencies
    (``single``: only the fifth, 2.89 cycles/m); a smooth sum of plane waves, or
    (``physical``) the exact field of a point scatterer at :data:`PHYSICAL_TARGET`."""
    freqs = np.linspace(2.0, 4.0, 10)
    if physical:
        field = fixtures.point_field(PHYSICAL_TARGET, (12, 12), 1 / 12, freqs)
    else:
        field = fixtures.smooth_field(n=12, frequencies=freqs, seed=1)
    return field.select([4]) if single else field


def _physical(spec: PluginSpec) -> bool:
    return Capability.PHYSICAL_PRIOR in spec.capabilities


def _family(spec: PluginSpec) -> str:
    factory = spec.load()
    return str(getattr(factory, "family", "") or spec.name)


def _tolerance(spec: PluginSpec) -> float:
    factory = spec.load()
    declared = getattr(factory, "conformance_tolerance", None)
    if declared is not None:
        return min(float(declared), MAX_TOLERANCE)
    return FIT_TOLERANCE.get(_family(spec), DEFAULT_TOLERANCE)


def _fitted(spec: PluginSpec, field: PhasorField | None = None, **options: Any) -> FieldModel:
    model = spec.create({**spec.test_config, **options})
    model.fit(fit_fixture(physical=_physical(spec)) if field is None else field)
    return model


def _briefly_fitted(spec: PluginSpec, field: PhasorField) -> FieldModel:
    """A model fitted for two steps where its config has ``steps`` (else as configured):
    for checks that need a fitted model, not a good fit (files, errors, counts)."""
    names = {f.name for f in dataclasses.fields(spec.config_class())}
    return _fitted(spec, field, **({"steps": 2} if "steps" in names else {}))


@requires(each=FREQUENCY_MODES)
def check_fits_smooth_field(spec: PluginSpec, single: bool) -> None:
    """Learns a sum of plane waves over (x, y, f) (``physical_prior``: a point scatterer's
    field) to the family's tolerance.

    Multi-frequency: trained on 9 of the 10 frequencies (every pixel); scored on all
    10 (the held-out frequency lies inside the band). Single-frequency: trained and
    scored on one frequency (every pixel). Scored against the closed-form field.
    Training from a random initialisation is itself random, so the score is the
    median over three seeds: one unlucky initialisation neither passes nor fails a model.
    """
    field = fit_fixture(single, _physical(spec))
    train = field if single else split_field(field, spatial_step=1, spectral="interleaved",
                                             spectral_fraction=0.1).train_field
    errors = []
    for seed in FIT_SEEDS:
        model = spec.create({**spec.test_config, "seed": seed})
        model.fit(train)
        pred = model.predict(field.wall_xyz[..., :2], field.frequencies)
        assert pred.shape == field.values.shape, (
            f"{spec.qualified_name}: predict returned {pred.shape}, expected "
            f"{field.values.shape}")
        errors.append(error_metrics(field.values, pred)["relative_l2"])
    err = float(np.median(errors))
    tol = _tolerance(spec)
    what = "one-frequency" if single else "point-scatterer" if _physical(spec) else "plane-wave"
    assert err <= tol, (f"{spec.qualified_name}: median relative L2 error {err:.4f} (seeds "
                        f"{FIT_SEEDS}: {np.round(errors, 4).tolist()}) on a smooth {what} "
                        f"field exceeds {tol} (with its test_config)")


@requires(each=FREQUENCY_MODES)
def check_predicts_unseen_points(spec: PluginSpec, single: bool) -> None:
    """Finite complex values of shape (F, ...) at unseen points (multi-frequency: and
    unseen frequencies, two outside the band).

    Also: a prediction at the training samples matches the closed-form field at
    least roughly (relative error < 0.5), so a model cannot ignore its inputs.
    """
    field = fit_fixture(single, _physical(spec))
    model = _fitted(spec, field)
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.55, 0.55, (7, 5, 2))          # inside and just outside the hull
    freqs = field.frequencies if single else np.array([1.9, 2.33, 3.1, 4.2])
    out = model.predict(pts, freqs)
    assert out.shape == (freqs.size, 7, 5), (
        f"{spec.qualified_name}: predict gave shape {out.shape}, expected "
        f"{(freqs.size, 7, 5)} for points (7, 5, 2) and {freqs.size} frequencies")
    assert np.iscomplexobj(out), f"{spec.qualified_name}: predict must return complex values"
    assert np.all(np.isfinite(out)), f"{spec.qualified_name}: predict returned NaN or inf"
    flat = model.predict(pts.reshape(-1, 2), freqs[:1])
    assert flat.shape == (1, 35), f"{spec.qualified_name}: (N, 2) points gave {flat.shape}"
    again = model.predict(field.wall_xyz[..., :2], field.frequencies)
    err = error_metrics(field.values, again)["relative_l2"]
    assert err < 0.5, f"{spec.qualified_name}: error {err:.3f} on its own training samples"


@requires(Capability.SAVE_LOAD, any_of=FREQUENCY_MODES)
def check_save_load_round_trip(spec: PluginSpec, single: bool) -> None:
    """save -> load -> predict gives identical output; foreign and corrupt files are refused."""
    factory = spec.load()
    field = fit_fixture(single, _physical(spec))
    model = _briefly_fitted(spec, field)
    pts = fixtures.wall_grid(9)[..., :2]
    freqs = field.frequencies if single else np.array([2.1, 3.05, 3.9])
    before = model.predict(pts, freqs)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.bin"
        model.save(path)
        assert path.is_file(), f"{spec.qualified_name}: save did not write {path} itself"
        loaded = factory.load(path)
        np.testing.assert_array_equal(loaded.predict(pts, freqs), before, err_msg=(
            f"{spec.qualified_name}: predictions changed after save -> load"))
        assert loaded.n_parameters == model.n_parameters, "parameter count changed on load"
        corrupt = Path(tmp) / "corrupt.bin"
        corrupt.write_bytes(path.read_bytes()[: max(1, path.stat().st_size // 3)])
        one_line_error(spec, "loading a truncated file", lambda: factory.load(corrupt))
        foreign = Path(tmp) / "foreign.npz"
        write_model_file(foreign, "no_such_model_xyz", FieldModelConfig(),
                         {"p0": np.zeros(3)})
        one_line_error(spec, "loading another model's file", lambda: factory.load(foreign))
        one_line_error(spec, "loading a missing file",
                        lambda: factory.load(Path(tmp) / "missing.npz"))


@requires(any_of=FREQUENCY_MODES)
def check_bad_input_rejected(spec: PluginSpec, single: bool) -> None:
    """One-line errors: predict before fit, empty or all-zero fields, bad frequencies."""
    fresh = spec.create(dict(spec.test_config))
    pts = fixtures.wall_grid(4)[..., :2]
    one_line_error(spec, "predict before fit", lambda: fresh.predict(pts, np.array([2.0])))
    field = fit_fixture(single, _physical(spec))
    zero = field.replace(values=np.zeros_like(field.values))
    one_line_error(spec, "fitting an all-zero field",
                    lambda: spec.create(dict(spec.test_config)).fit(zero))
    empty = PhasorField(values=np.zeros((0, 4, 4), np.complex64), frequencies=np.zeros(0),
                        wall_xyz=fixtures.wall_grid(4),
                        geometry=CaptureGeometry(kind=CaptureKind.SINGLE_SPOT,
                                                 laser_point=np.zeros(3)))
    one_line_error(spec, "fitting an empty field",
                    lambda: spec.create(dict(spec.test_config)).fit(empty))
    model = _briefly_fitted(spec, field)
    for bad in (np.array([np.nan]), np.array([np.inf]), np.array([0.0]), np.array([-2.0])):
        one_line_error(spec, f"predicting at frequency {bad[0]}",
                       partial(model.predict, pts, bad))
    one_line_error(spec, "predicting at NaN points",
                    lambda: model.predict(np.full((3, 2), np.nan), np.array([2.0])))


@requires(any_of=FREQUENCY_MODES)
def check_parameter_count(spec: PluginSpec, single: bool) -> None:
    """n_parameters is a positive integer; each preset has its thesis count in its saved file.

    Models may declare ``presets()`` -> {name: preset with ``options`` and ``parameters``}.
    A preset is fitted for two steps on a one-frequency field; ``n_parameters`` and (for
    models with ``weights()``, the arrays of the backend) the number of trained values
    must equal the declared count.
    """
    factory = spec.load()
    model = _briefly_fitted(spec, fit_fixture(single, _physical(spec)))
    n = model.n_parameters
    assert isinstance(n, (int, np.integer)) and n > 0, (
        f"{spec.qualified_name}: n_parameters must be a positive integer, got {n!r}")
    presets = getattr(factory, "presets", None)
    if presets is None:
        return
    one = fit_fixture(single=True, physical=_physical(spec))
    for name, preset in presets().items():
        options = {**dict(preset.options), "steps": 2, "eval_every": 1, "device": "cpu"}
        m = spec.create(options)
        m.fit(one)
        assert m.n_parameters == preset.parameters, (
            f"{spec.qualified_name}: preset {name} has {m.n_parameters} parameters, the thesis "
            f"network has {preset.parameters}")
        weights = getattr(m, "weights", None)
        if weights is not None:
            stored = sum(int(np.asarray(w).size) for w in weights())
            assert stored == preset.parameters, (
                f"{spec.qualified_name}: preset {name} holds {stored} weights, expected "
                f"{preset.parameters}")


@requires(Capability.NEURAL, any_of=FREQUENCY_MODES)
def check_seed_changes_fit(spec: PluginSpec, single: bool) -> None:
    """A neural model starts from a random initialisation drawn from its seed: seeds 0 and
    1 fit different models (predictions differ by more than 1e-4 relative)."""
    field = fit_fixture(single, _physical(spec))
    pts = fixtures.wall_grid(9)[..., :2]
    first, second = (_fitted(spec, field, seed=seed).predict(pts, field.frequencies)
                     for seed in (0, 1))
    change = float(np.max(np.abs(first - second)) / max(np.max(np.abs(first)), 1e-300))
    assert change > 1e-4, (
        f"{spec.qualified_name}: seeds 0 and 1 fit the same model (largest change "
        f"{change:.3g} relative); the seed must reach the initialisation")


MODEL_CHECKS = (
    check_fits_smooth_field,
    check_predicts_unseen_points,
    check_save_load_round_trip,
    check_bad_input_rejected,
    check_parameter_count,
    check_seed_changes_fit,
)

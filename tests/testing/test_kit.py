"""The conformance kit picks its checks from declared capabilities, and the checks can fail."""

import subprocess
import sys
import types

import numpy as np
import pytest

from nlosfw import Capability, ConfigError, DataError, PluginError, PluginKind
from nlosfw.image.fft import FFTImager
from nlosfw.plugins import CAPABILITIES, DEFAULT_CAPABILITIES, hookimpl, load_plugins
from nlosfw.testing import (
    GEOMETRIES,
    check_cases,
    check_plan,
    checks_for,
    combine,
    parametrize_with_checks,
    requires,
    spec_of,
    variant,
)
from nlosfw.testing.kit import pytest_params
from nlosfw.testing.selection import DEVICE_LEGS, plan_check
from nlosfw.transform.wavelet import WaveletTransform

HOOKS = {"simulator": "register_simulators", "transform": "register_phasor_transforms",
         "model": "register_field_models", "imager": "register_imagers"}
#: The built-in implementations the fake plugins reuse, under other names.
FACTORIES = {
    "simulator": "nlosfw.simulate.analytic:AnalyticSimulator",
    "transform": "nlosfw.transform.fft:FFTTransform",
    "model": "nlosfw.model.interp:InterpFieldModel",
    "imager": "nlosfw.image.fft:FFTImager",
}


class DelayedWavelet(WaveletTransform):
    """Liu's wavelet whose weights carry a 0.3 m delay: its pulse is not centred at t = 0."""

    def transform(self, capture):
        field = super().transform(capture)
        return field.replace(weights=field.weights * np.exp(-2j * np.pi * field.frequencies * 0.3))


def fake_module(kind, name, factory=None, **register_kwargs):
    """A plugin module registering one plugin ``name`` of ``kind``."""

    def register_hook(register):
        register(name, factory or FACTORIES[kind], **register_kwargs)

    module = types.ModuleType(f"fake_{name}")
    setattr(module, HOOKS[kind], hookimpl(register_hook))
    return module


def fake_spec(kind, name, factory=None, **register_kwargs):
    """The spec of one fake plugin, registered in-process through ``load_plugins(extra=...)``."""
    host = load_plugins(env={"NLOSFW_PLUGINS": name},
                        extra=[("nlosfw-fake", "fake", fake_module(kind, name, factory,
                                                                    **register_kwargs))])
    return host.registry.get(kind, name)


def planned(spec):
    plan = check_plan(spec)
    return ({p.name for p in plan.applied}, {p.name: p.skip_reason for p in plan.skipped})


# ----------------------------------------------------------------------- vocabulary
def test_every_kind_has_a_vocabulary_and_defaults_inside_it():
    for kind in PluginKind:
        assert set(DEFAULT_CAPABILITIES[kind.value]) <= set(CAPABILITIES[kind.value])
    assert set(CAPABILITIES["capture_format"]) == {Capability.READABLE, Capability.WRITABLE}
    assert set(CAPABILITIES["simulator"]) == {
        Capability.CONFOCAL, Capability.SINGLE_SPOT, Capability.DEVICE_LEGS,
        Capability.OCCLUSION, Capability.MESH_FILES, Capability.GPU}


def test_unknown_capability_is_a_one_line_error_naming_plugin_and_valid_names():
    with pytest.raises(PluginError) as info:
        fake_spec("simulator", "typo", capabilities=["confocal", "occlusoin"])
    assert str(info.value) == (
        "nlosfw-fake: simulator plugin 'typo' declares unknown capability 'occlusoin'; valid: "
        "confocal, device_legs, gpu, mesh_files, occlusion, single_spot")
    with pytest.raises(PluginError, match=r"^nlosfw-fake: simulator plugin 'wrongkind' declares "
                       r"unknown capability 'neural'; valid: confocal, "):
        fake_spec("simulator", "wrongkind", capabilities=[Capability.NEURAL])
    with pytest.raises(PluginError, match=r"capabilities must be a list of names, not 'confocal'"):
        fake_spec("imager", "bare", capabilities="confocal")


def test_declared_capabilities_are_stored_and_nothing_declared_means_the_defaults():
    spec = fake_spec("imager", "mixed", capabilities=["confocal", Capability.PLANE_VOXELS])
    assert spec.capabilities == {Capability.CONFOCAL, Capability.PLANE_VOXELS}
    assert spec.declared_capabilities == (Capability.CONFOCAL, Capability.PLANE_VOXELS)
    silent = fake_spec("imager", "silent")
    assert silent.declared_capabilities is None
    assert silent.capabilities == {Capability.SINGLE_SPOT, Capability.CONFOCAL,
                                   Capability.PLANE_VOXELS, Capability.RSD}
    assert "(declares none: the kind's defaults)" in check_plan(silent).format()


# ----------------------------------------------------------------------- selection
def test_a_plugin_gets_exactly_the_checks_of_its_capabilities():
    spec = fake_spec("simulator", "spot_only", capabilities=["single_spot"])
    applied, skipped = planned(spec)
    assert applied == {
        "check_interface", "check_config_round_trip", "check_bad_config_rejected",
        "check_deterministic[single_spot]", "check_no_heavy_import_at_registration",
        "check_capture_layout[single_spot]", "check_onset_matches_path_length[single_spot]",
        "check_absolute_energy[single_spot]", "check_energy_falloff[single_spot]",
        "check_bad_scene_rejected[single_spot]"}
    who = "which simulator:spot_only does not declare"
    assert skipped == {
        "check_capture_layout[single_spot+device_legs]":
            f"needs capability device_legs, {who}",
        "check_capture_layout[confocal]": f"needs capability confocal, {who}",
        "check_capture_layout[confocal+device_legs]":
            f"needs capabilities confocal and device_legs, {who}",
        "check_onset_matches_path_length[single_spot+device_legs]":
            f"needs capability device_legs, {who}",
        "check_onset_matches_path_length[confocal]": f"needs capability confocal, {who}",
        "check_onset_matches_path_length[confocal+device_legs]":
            f"needs capabilities confocal and device_legs, {who}",
        "check_absolute_energy[confocal]": f"needs capability confocal, {who}",
        "check_energy_falloff[confocal]": f"needs capability confocal, {who}",
        "check_occlusion": f"needs capability occlusion, {who}",
        "check_mesh_file_matches_patch": f"needs capability mesh_files, {who}",
    }
    every = {p.check for p in check_plan(spec).checks}
    assert every == set(checks_for("simulator"))


def test_pytest_reports_inapplicable_checks_as_skipped_with_the_reason():
    spec = fake_spec("simulator", "spot_only", capabilities=["single_spot"])
    params = {p.id: p for p in pytest_params((spec, c) for c in check_plan(spec).checks)}
    occlusion = params["simulator:spot_only-check_occlusion"]
    assert [(m.name, m.kwargs["reason"]) for m in occlusion.marks] == [
        ("skip", "needs capability occlusion, which simulator:spot_only does not declare")]
    assert list(params["simulator:spot_only-check_absolute_energy[single_spot]"].marks) == []
    mark = parametrize_with_checks(registry=load_plugins(env={}).registry, names=["analytic"])
    ids = [p.id for p in mark.args[1]]
    assert "simulator:analytic-check_occlusion" in ids
    assert "simulator:analytic-check_capture_layout[confocal+device_legs]" in ids


def test_a_confocal_only_imager_is_checked_in_that_geometry_only():
    """A classical imager (LCT, f-k) declares confocal only; here the rsd imager stands in."""
    spec = fake_spec("imager", "confocal_only", "nlosfw.image.rsd:RSDImager",
                     capabilities=["confocal", "plane_voxels"], test_config={"chunk_mb": 1.0})
    applied, skipped = planned(spec)
    assert "check_imager_focuses_point[confocal]" in applied
    assert skipped["check_imager_focuses_point[single_spot]"] == (
        "needs capability single_spot, which imager:confocal_only does not declare")
    assert "check_deterministic[plane_voxels+confocal]" in applied
    [focus] = [p for p in check_plan(spec).applied if p.name.startswith("check_imager_focuses")]
    focus(spec)                                           # the check itself runs and passes


def test_variants_and_requirements():
    axes = combine(GEOMETRIES, DEVICE_LEGS)
    assert [v.name for v in axes] == ["single_spot", "single_spot+device_legs", "confocal",
                                      "confocal+device_legs"]
    assert axes[3].needs == {Capability.CONFOCAL, Capability.DEVICE_LEGS}
    assert dict(axes[3].options) == {"confocal": True, "legs": True}

    @requires(Capability.NEURAL, any_of={"model": (variant("a", [Capability.SAVE_LOAD], x=1),
                                                   variant("b", [], x=2))})
    def check_demo(spec, x):
        assert x == 2

    interp = load_plugins(env={}).registry.get("model", "interp")
    [skip] = plan_check(interp, check_demo)
    assert skip.skip_reason == "needs capability neural, which model:interp does not declare"
    neural = fake_spec("model", "plain_neural", capabilities=["neural"])
    [run] = plan_check(neural, check_demo)
    assert run.name == "check_demo[b]" and run.applies      # 'a' needs save_load
    run(neural)
    with pytest.raises(ValueError):
        requires(each=GEOMETRIES, any_of=GEOMETRIES)


def test_expected_failures_must_name_a_check_and_run_as_strict_xfail():
    with pytest.raises(PluginError, match=r"^nlosfw-fake: simulator plugin 'bad_xfail': "
                       r"expected_failures names no check of the kit: check_nope; valid: "):
        check_plan(fake_spec("simulator", "bad_xfail", expected_failures={"check_nope": "x"}))
    spec = fake_spec("simulator", "known_bug", expected_failures={
        "check_occlusion[confocal]": "bug 123: shadows wrong in confocal scans"})
    params = {p.id: p for p in pytest_params((spec, c) for c in check_plan(spec).checks)}
    [mark] = params["simulator:known_bug-check_occlusion[confocal]"].marks
    assert mark.name == "xfail" and mark.kwargs["strict"] is True
    assert list(params["simulator:known_bug-check_occlusion[single_spot]"].marks) == []


def test_a_plugin_missing_a_system_library_is_skipped_saying_what_to_install(tmp_path,
                                                                              monkeypatch):
    """Its ``system_check`` names what the machine lacks: every check skips with that line,
    unless NLOSFW_REQUIRE_SYSTEM=1 (CI, which installs it), where the checks run."""
    (tmp_path / "fake_probe.py").write_text(
        "def lacking():\n    return 'no libfoo: apt-get install -y libfoo'\n"
        "def broken():\n    raise OSError('probe crashed')\n"
        "def fine():\n    return ''\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("NLOSFW_REQUIRE_SYSTEM", raising=False)

    def marks(check: str) -> list:
        spec = fake_spec("simulator", f"needs_{check}", system_check=f"fake_probe:{check}")
        params = pytest_params((spec, c) for c in check_plan(spec).applied)
        assert params
        return [[(m.name, m.kwargs.get("reason")) for m in p.marks] for p in params]

    reason = "simulator:needs_lacking: no libfoo: apt-get install -y libfoo"
    assert {str(m) for m in marks("lacking")} == {str([("skip", reason)])}
    assert all(m == [("skip", "simulator:needs_broken: nlosfw-fake: simulator plugin "
                      "'needs_broken': its system check fake_probe:broken failed: OSError: "
                      "probe crashed")] for m in marks("broken"))
    assert all(m == [] for m in marks("fine"))
    monkeypatch.setenv("NLOSFW_REQUIRE_SYSTEM", "1")
    assert all(m == [] for m in marks("lacking"))


# ------------------------------------------------------------ declaring what it lacks fails
LIES = [
    # (kind, factory or None, capabilities, planned check, error, message pattern)
    ("simulator", None, ["single_spot", "occlusion"], "check_occlusion[single_spot]",
     AssertionError, "no visibility test"),
    ("simulator", None, ["confocal", "occlusion"], "check_occlusion[confocal]",
     AssertionError, "no visibility test"),
    ("simulator", None, ["single_spot", "mesh_files"], "check_mesh_file_matches_patch"
     "[single_spot]", ConfigError, r"scene\.geometry\[0\]\.type"),
    ("transform", None, ["single_spot", "spectral_weights"],
     "check_weights_form_centred_pulse[single_spot]", AssertionError, "has no weights"),
    ("transform", DelayedWavelet, ["single_spot", "spectral_weights"],
     "check_weights_form_centred_pulse[single_spot]", AssertionError, "peaks at t = 0.3"),
    ("transform", None, ["single_spot", "gaussian_wavelet"],
     "check_wavelet_weights_are_kernel_spectrum[single_spot]", AssertionError,
     "must derive from WaveletTransformConfig"),
    ("transform", "nlosfw.transform.wavelet:WaveletTransform", ["confocal", "any_frequencies"],
     "check_transform_at_requested_frequencies[confocal]", ConfigError, "frequencies"),
    ("model", None, ["multi_frequency", "neural"], "check_seed_changes_fit[multi_frequency]",
     AssertionError, "seeds 0 and 1 fit the same model"),
    ("imager", None, ["single_spot", "point_voxels", "rsd"],
     "check_imager_point_voxels[single_spot]",
     DataError, "planes parallel to the wall"),
]


@pytest.mark.parametrize("kind, factory, capabilities, check, error, message", LIES,
                         ids=[lie[3] for lie in LIES])
def test_declaring_a_capability_the_plugin_lacks_fails_its_check(kind, factory, capabilities,
                                                                 check, error, message):
    spec = fake_spec(kind, "liar", factory, capabilities=capabilities)
    [case] = [p for p in check_plan(spec).applied if p.name == check]
    with pytest.raises(error, match=message):
        case(spec)


# ----------------------------------------------------------------------- command line
def test_command_prints_the_plan_and_runs_the_checks(tmp_path):
    plan = subprocess.run([sys.executable, "-m", "nlosfw.testing", "analytic", "--plan"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert plan.returncode == 0, plan.stderr
    assert ("  skip  check_occlusion: needs capability occlusion, which simulator:analytic "
            "does not declare") in plan.stdout
    assert "  run   check_capture_layout[confocal+device_legs]" in plan.stdout
    run = subprocess.run([sys.executable, "-m", "nlosfw.testing", "model:interp", "-q"],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stdout[-2000:]
    assert "13 passed, 1 skipped" in run.stdout
    assert not list(tmp_path.iterdir()), "the command must not write into the directory"
    bad = subprocess.run([sys.executable, "-m", "nlosfw.testing", "no_such_plugin"],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert bad.returncode == 2
    assert bad.stderr.startswith("error: unknown plugin 'no_such_plugin'; valid: ")
    assert bad.stderr.count("\n") == 1


# ------------------------------------------------------------ capabilities on the class
class _ConfocalOnlyImager(FFTImager):
    """An FFT imager that declares, on its class, that it images confocal fields only."""

    capabilities = ("confocal", Capability.PLANE_VOXELS)


class _TypoImager(FFTImager):
    capabilities = ("confocal", "plane_voxel")


def test_capabilities_declared_on_the_class_are_read_by_the_registry_and_the_kit():
    spec = fake_spec("imager", "classy", factory=_ConfocalOnlyImager)
    assert spec.declared_capabilities is None
    assert spec.capabilities == {Capability.CONFOCAL, Capability.PLANE_VOXELS}
    assert spec.capabilities_origin == "class"
    applied, skipped = planned(spec)
    assert "check_imager_focuses_point[confocal]" in applied
    assert "check_imager_focuses_point[single_spot]" in skipped


def test_capabilities_given_to_register_take_the_place_of_the_class_ones():
    spec = fake_spec("imager", "both", factory=_ConfocalOnlyImager,
                     capabilities=["single_spot", "plane_voxels"])
    assert spec.capabilities == {Capability.SINGLE_SPOT, Capability.PLANE_VOXELS}
    assert spec.capabilities_origin == "registration"


def test_an_unknown_capability_on_the_class_is_a_one_line_error():
    spec = fake_spec("imager", "typo_class", factory=_TypoImager)
    with pytest.raises(PluginError, match=r"^nlosfw-fake: imager plugin 'typo_class' declares "
                       r"unknown capability 'plane_voxel'; valid: "):
        _ = spec.capabilities


def test_the_kit_checks_a_plugin_instance_with_its_config_and_class_capabilities():
    imager = _ConfocalOnlyImager({"workers": 1})
    spec = spec_of(imager)
    assert (spec.kind, spec.name) == (PluginKind.IMAGER, "_ConfocalOnlyImager")
    assert spec.test_config["workers"] == 1
    assert spec.capabilities == {Capability.CONFOCAL, Capability.PLANE_VOXELS}
    assert spec.create(dict(spec.test_config)).config == imager.config
    ids = [p.id for p in pytest_params(check_cases(plugins=[imager]))]
    assert "imager:_ConfocalOnlyImager-check_config_round_trip" in ids
    checks = {p.values[1].name: p.values[1] for p in pytest_params(check_cases(plugins=[imager]))}
    checks["check_config_round_trip"](spec)          # runs on the instance's spec
    with pytest.raises(PluginError, match="implements none of the plugin interfaces"):
        spec_of(object())  # type: ignore[arg-type]

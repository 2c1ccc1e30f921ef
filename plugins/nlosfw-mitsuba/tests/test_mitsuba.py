"""The mitsuba simulator against physics and against the embree simulator."""

from __future__ import annotations

import logging
import os
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest
from nlosfw_mitsuba.llvm import configure_llvm, find_libllvm, llvm_problem, llvm_version

from nlosfw.common import ConfigError, PluginError
from nlosfw.simulate import builtin_scene
from nlosfw.testing import analytic_agreement, rendered, scene_with

TILTED = [{"type": "rectangle", "position": [0.1, -0.05, 0.6], "size": [0.3, 0.2],
           "rotation": [10.0, -20.0, 5.0], "albedo": 0.7}]


# --------------------------------------------------------------------------- LLVM
def test_llvm_versions_from_file_names():
    assert llvm_version("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1") == 19
    assert llvm_version("libLLVM-18.so") == 18
    assert llvm_version("libLLVM-15.so.1") == 15
    assert llvm_version("/usr/lib/llvm-17/lib/libLLVM.so") == 17
    assert llvm_version("/opt/homebrew/opt/llvm/lib/libLLVM.dylib") is None


def test_llvm_search_prefers_the_newest_and_never_15(tmp_path: Path):
    for name in ("libLLVM-15.so.1", "libLLVM.so.17.0", "libLLVM-19.so"):
        (tmp_path / name).write_bytes(b"\x7fELF")
    assert find_libllvm(env={}, dirs=[str(tmp_path)]) == str(tmp_path / "libLLVM-19.so")
    (tmp_path / "libLLVM-19.so").unlink()
    (tmp_path / "libLLVM.so.17.0").unlink()
    with pytest.raises(PluginError, match="apt-get install -y libllvm19") as err:
        find_libllvm(env={}, dirs=[str(tmp_path)])
    assert "\n" not in str(err.value)


def test_llvm_environment_variable_is_honoured(tmp_path: Path):
    lib = tmp_path / "libLLVM-custom.so"
    lib.write_bytes(b"\x7fELF")
    env = {"DRJIT_LIBLLVM_PATH": str(lib)}
    assert configure_llvm(env=env, dirs=[]) == str(lib)
    env = {}
    (tmp_path / "libLLVM.so.18.1").write_bytes(b"\x7fELF")
    assert configure_llvm(env=env, dirs=[str(tmp_path)]) == str(tmp_path / "libLLVM.so.18.1")
    assert env["DRJIT_LIBLLVM_PATH"] == str(tmp_path / "libLLVM.so.18.1")
    with pytest.raises(PluginError, match="DRJIT_LIBLLVM_PATH"):
        find_libllvm(env={"DRJIT_LIBLLVM_PATH": str(tmp_path / "nope.so")})


def test_without_llvm_the_plugin_says_in_one_line_what_to_install(tmp_path: Path,
                                                                   monkeypatch):
    """Its system check: the conformance kit and the tests below skip with this line."""
    from nlosfw.plugins import load_plugins
    from nlosfw.testing import system_problem

    spec = load_plugins(env={}).registry.get("simulator", "mitsuba")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(tmp_path / "libLLVM.so.19.1"))
    problem = system_problem(spec)
    assert problem == llvm_problem()
    assert "apt-get install -y libllvm19" in problem and "\n" not in problem
    (tmp_path / "libLLVM.so.19.1").write_bytes(b"\x7fELF")
    assert system_problem(spec) == ""


# --------------------------------------------------------------------------- rendering
# find_spec, not import: mitsuba must be imported by the plugin, after it chose an LLVM
if find_spec("mitsuba") is None or find_spec("mitransient") is None:
    pytest.skip("mitsuba and mitransient are not installed", allow_module_level=True)
#: The rendering tests need Dr.Jit's LLVM: without it they skip saying what to install,
#: unless NLOSFW_REQUIRE_SYSTEM=1 (CI installs it), where they run and fail.
renders = pytest.mark.skipif(os.environ.get("NLOSFW_REQUIRE_SYSTEM") != "1"
                             and bool(llvm_problem()), reason=llvm_problem() or "LLVM found")

from nlosfw_mitsuba.simulator import MitsubaSimulator  # noqa: E402


@renders
@pytest.mark.parametrize("capture", [{}, {"type": "confocal"}, {"device_legs": True},
                                     {"type": "confocal", "device_legs": True}],
                         ids=["single", "confocal", "legs", "confocal-legs"])
def test_agrees_with_analytic_in_absolute_value(capture):
    """Same radiometric scale (the projector factor divided out), bins and grid order."""
    scene = scene_with(TILTED, **capture)
    agree = analytic_agreement(MitsubaSimulator({"spp": 8192}), scene)
    assert agree.total == pytest.approx(1.0, abs=0.01)
    assert agree.worst_sensor < 0.03
    assert agree.relative_l2 < 0.08


@renders
@pytest.mark.slow
def test_time_profiles_agree_with_embree():
    """thesis_two_planes on a coarse grid: per-sensor profiles correlate, onsets agree."""
    if find_spec("embreex") is None or find_spec("nlosfw_embree") is None:
        pytest.skip("the embree simulator is not installed")
    from nlosfw_embree.simulator import EmbreeSimulator

    scene = builtin_scene("thesis_two_planes", wall={"resolution": [16, 12]},
                          time={"bins": 512, "bin_width": 0.01})
    a = rendered(MitsubaSimulator({"spp": 1 << 15}), scene).H.astype(float)
    b = rendered(EmbreeSimulator({"samples": 1 << 16}), scene).H.astype(float)
    pa, pb = a.reshape(a.shape[0], -1).T, b.reshape(b.shape[0], -1).T
    za = (pa - pa.mean(1, keepdims=True)) / pa.std(1, keepdims=True)
    zb = (pb - pb.mean(1, keepdims=True)) / pb.std(1, keepdims=True)
    correlation = (za * zb).mean(axis=1)
    assert correlation.mean() >= 0.99, correlation.mean()
    onset_a = np.argmax(pa >= 0.01 * pa.max(1, keepdims=True), axis=1)
    onset_b = np.argmax(pb >= 0.01 * pb.max(1, keepdims=True), axis=1)
    assert np.abs(onset_a - onset_b).max() <= 1
    assert a.sum() / b.sum() == pytest.approx(1.0, abs=0.01)


@renders
@pytest.mark.slow
def test_hidden_geometry_sampling_overcounts_shadowing_and_warns(caplog):
    """Documented mitransient behaviour, and the unbiased alternative, against embree."""
    if find_spec("embreex") is None or find_spec("nlosfw_embree") is None:
        pytest.skip("the embree simulator is not installed")
    from nlosfw_embree.simulator import EmbreeSimulator

    scene = builtin_scene("thesis_occluded", wall={"resolution": [12, 12]},
                          time={"bins": 384, "bin_width": 0.016})
    truth = rendered(EmbreeSimulator({"samples": 1 << 16}), scene).H.sum()
    with caplog.at_level(logging.WARNING, logger="nlosfw_mitsuba"):
        biased = rendered(MitsubaSimulator({"spp": 2048}), scene)
    assert "counts that light twice" in caplog.text
    assert biased.H.sum() > 1.1 * truth
    assert biased.scene_info["render"]["blocked_sight_line_fraction"] > 0.05
    unbiased = MitsubaSimulator({"spp": 1 << 16, "hidden_geometry_sampling": False})
    assert rendered(unbiased, scene).H.sum() / truth == pytest.approx(1.0, abs=0.03)


def test_point_scatterers_are_refused():
    scene = scene_with([{"type": "point", "position": [0.0, 0.0, 0.5]}])
    with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.type: .*point"):
        MitsubaSimulator().simulate(scene)


@renders
def test_geometry_blocking_the_device_is_refused():
    scene = scene_with([{"type": "rectangle", "position": [0.0, 0.0, 0.2], "size": [0.8, 0.8]}],
                       sensor_position=[0.0, 0.0, 0.5], laser_position=[0.3, 0.0, 0.1])
    with pytest.raises(ConfigError, match=r"scene\.capture\.sensor_position"):
        rendered(MitsubaSimulator({"spp": 16}), scene)


@renders
def test_bounce_filter_and_passes():
    scene = scene_with(TILTED, resolution=(6, 5))
    third = rendered(MitsubaSimulator({"spp": 2048}), scene)
    passes = rendered(MitsubaSimulator({"spp": 2048, "spp_per_pass": 512}), scene)
    assert passes.scene_info["render"]["passes"] == 4
    assert passes.H.sum() / third.H.sum() == pytest.approx(1.0, abs=0.01)
    assert not np.array_equal(passes.H, third.H)          # passes use different seeds
    fourth = rendered(MitsubaSimulator({"spp": 256, "bounces": 4, "max_bounces": 4}), scene)
    assert fourth.H.sum() == 0                            # one plane: no fourth bounce

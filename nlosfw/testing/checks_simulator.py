"""Conformance checks for every simulator plugin (see :mod:`nlosfw.testing.checks_common`).

Every expected number comes from :mod:`nlosfw.simulate.physics` evaluated on a dense
grid of points over the hidden patch (an independent quadrature), never from
the simulator under test. Scenes are tiny (a 1 m wall, 8 x 8 sensors, a few
hundred bins) and simulators run with their registered ``test_config``.

Each check runs once per capture geometry the simulator declares (``single_spot``,
``confocal``), with and without device legs where it declares ``device_legs``;
``occlusion`` and ``mesh_files`` add their own checks.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from functools import partial
from pathlib import Path

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import GridFormat, HFormat
from nlosfw.common.errors import ConfigError
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.registry import PluginSpec
from nlosfw.simulate.interface import Simulator
from nlosfw.simulate.physics import bin_index, three_bounce
from nlosfw.simulate.scene import Scene, scene_from_config
from nlosfw.testing import fixtures
from nlosfw.testing.checks_common import one_line_error
from nlosfw.testing.selection import DEVICE_LEGS, GEOMETRIES, combine, requires

#: Energy and energy-ratio tolerance (relative).
ENERGY_RTOL = 0.05


def _simulate(spec: PluginSpec, scene: Scene) -> Capture:
    return spec.create(dict(spec.test_config)).simulate(scene)


def _patch_quadrature(scene: Scene, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Exact-physics (path, weight) of every (patch point, sensor) pair, (n^2, S) each.

    Uses the scene's first item, a wall-facing patch or rectangle, split into n x n
    cells evaluated at their centres with :func:`nlosfw.simulate.physics.three_bounce`.
    """
    item = scene.geometry[0]
    w, h = item.size
    u = (np.arange(n) + 0.5) / n - 0.5
    gx, gy = np.meshgrid(u * w, u * h, indexing="ij")
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1) + np.asarray(item.position)
    normals = np.tile([0.0, 0.0, -1.0], (pts.shape[0], 1))
    area = np.full(pts.shape[0], item.albedo * w * h / pts.shape[0])
    sensors = scene.wall.grid_xyz().reshape(-1, 3)
    laser = sensors if scene.is_confocal else scene.laser_spot_xyz()
    path, weight = three_bounce(laser, pts, normals, area, sensors)
    return path + scene.device_path(sensors)[None, :], weight


def _profiles(H: np.ndarray) -> np.ndarray:
    """(S, T) time profiles in the order of the flattened sensor grid."""
    return np.moveaxis(np.asarray(H, dtype=float), 0, -1).reshape(-1, H.shape[0])


@requires(each=combine(GEOMETRIES, DEVICE_LEGS))
def check_capture_layout(spec: PluginSpec, confocal: bool, legs: bool) -> None:
    """Layout, dtype, units and metadata are those of the scene, and survive HDF5."""
    from nlosfw.capture.hdf5 import read_capture, write_capture

    scene = fixtures.tiny_scene(confocal=confocal, device_legs=legs, bins=400)
    capture = _simulate(spec, scene)
    where = f"{spec.qualified_name} (confocal={confocal}, device_legs={legs})"
    nx, ny = scene.wall.resolution
    assert capture.H.dtype == np.float32, f"{where}: H must be float32, got {capture.H.dtype}"
    assert capture.H.shape == (scene.time.bins, nx, ny), (
        f"{where}: H shape {capture.H.shape}, expected (bins, X, Y) = "
        f"{(scene.time.bins, nx, ny)}")
    assert capture.H_format is HFormat.T_Sx_Sy
    assert capture.sensor_grid_format is GridFormat.X_Y_3
    np.testing.assert_allclose(capture.sensor_grid_xyz, scene.wall.grid_xyz(), atol=1e-12,
                               err_msg=f"{where}: sensor grid differs from the scene's")
    assert capture.delta_t == scene.time.bin_width and capture.t_start == scene.time.start, (
        f"{where}: time axis ({capture.t_start}, {capture.delta_t}) is not the scene's "
        f"({scene.time.start}, {scene.time.bin_width}) metres")
    assert capture.t_accounts_first_and_last_bounces == legs
    assert capture.is_confocal == confocal, f"{where}: capture kind is {capture.kind}"
    assert np.all(capture.H >= 0) and capture.H.sum() > 0, f"{where}: H must be >= 0, not 0"
    for key in ("scene", "simulator", "ground_truth", "noise"):
        assert key in capture.scene_info, f"{where}: scene_info lacks '{key}'"
    depth = np.asarray(capture.scene_info["ground_truth"]["depth"])
    assert depth.shape == (nx, ny), f"{where}: ground-truth depth shape {depth.shape}"
    with tempfile.TemporaryDirectory() as tmp:
        path = write_capture(Path(tmp) / "capture.hdf5", capture)
        again = read_capture(path)
    np.testing.assert_array_equal(again.H, capture.H, err_msg=f"{where}: H changed in HDF5")
    assert again.delta_t == capture.delta_t and again.t_start == capture.t_start
    assert again.is_confocal == confocal
    assert again.scene_info["ground_truth"]["depth"] == capture.scene_info["ground_truth"][
        "depth"], f"{where}: ground truth changed in HDF5"


@requires(each=combine(GEOMETRIES, DEVICE_LEGS))
def check_onset_matches_path_length(spec: PluginSpec, confocal: bool, legs: bool) -> None:
    """A 1 cm patch: every sensor's profile starts at the analytic shortest path (+-1 bin).

    With device legs, the time window does not start at 0.
    """
    start = 0.8 if legs else 0.0
    config = fixtures.tiny_scene_config(confocal=confocal, device_legs=legs,
                                        bins=320, patch=0.01)
    config["time"]["start"] = start
    scene = scene_from_config(config)
    H = _profiles(_simulate(spec, scene).H)
    path, _ = _patch_quadrature(scene)
    expected = bin_index(path.min(axis=0), start, scene.time.bin_width)
    peak = H.max(axis=1)
    assert np.all(peak > 0), (f"{spec.qualified_name}: sensors without signal "
                              f"(confocal={confocal}, device_legs={legs})")
    onset = np.argmax(H / peak[:, None] >= 0.01, axis=1)
    off = np.abs(onset - expected)
    assert off.max() <= 1, (
        f"{spec.qualified_name} (confocal={confocal}, device_legs={legs}): onset bins "
        f"differ from the analytic path length by up to {off.max()} bins "
        f"(sensor {int(off.argmax())}: {onset[off.argmax()]} vs {expected[off.argmax()]})")


@requires(each=GEOMETRIES)
def check_absolute_energy(spec: PluginSpec, confocal: bool) -> None:
    """Total and per-sensor energy of a 4 cm patch match nlosfw.simulate.physics within 5%.

    The patch is off-centre, so a transposed sensor grid or a missing cosine
    changes the per-sensor totals.
    """
    scene = fixtures.tiny_scene(confocal=confocal, bins=400)
    H = _profiles(_simulate(spec, scene).H)
    _, weight = _patch_quadrature(scene)
    expected = weight.sum(axis=0)
    got = H.sum(axis=1)
    total = got.sum() / expected.sum()
    assert abs(total - 1) < ENERGY_RTOL, (
        f"{spec.qualified_name} (confocal={confocal}): total energy is {total:.4f} x the "
        "analytic value; every simulator must follow the radiometric convention of "
        "nlosfw.simulate.physics")
    ratio = got / expected
    worst = int(np.argmax(np.abs(ratio - 1)))
    assert np.all(np.abs(ratio - 1) < ENERGY_RTOL), (
        f"{spec.qualified_name} (confocal={confocal}): sensor {worst} has {ratio[worst]:.4f}"
        " x the analytic energy (a transposed grid or a wrong cosine?)")


@requires(each=GEOMETRIES)
def check_energy_falloff(spec: PluginSpec, confocal: bool) -> None:
    """Moving a 4 cm patch from 1 m to 2 m changes the energy by the analytic ratio (5%)."""
    totals, expected = [], []
    for depth in (1.0, 2.0):
        scene = fixtures.tiny_scene(target=(0.0, 0.0, depth), bins=600, confocal=confocal)
        totals.append(float(_simulate(spec, scene).H.sum(dtype=np.float64)))
        expected.append(float(_patch_quadrature(scene)[1].sum()))
    got, want = totals[1] / totals[0], expected[1] / expected[0]
    assert abs(got / want - 1) < ENERGY_RTOL, (
        f"{spec.qualified_name} (confocal={confocal}): energy ratio 2 m / 1 m is {got:.5f}, "
        f"physics says {want:.5f}")


@requires(Capability.OCCLUSION, each=GEOMETRIES)
def check_occlusion(spec: PluginSpec, confocal: bool) -> None:
    """A patch hidden behind a plate (from the laser spot and every sensor) adds no light.

    The patch's paths are longer than any of the plate's, so the bins they would
    fill must stay empty.
    """
    config = fixtures.tiny_scene_config(bins=400, target=(0.0, 0.0, 1.5), patch=0.04,
                                        confocal=confocal)
    config["geometry"].append({"type": "rectangle", "position": [0.0, 0.0, 0.3],
                               "size": [0.9, 0.9]})
    scene = scene_from_config(config)
    H = _profiles(_simulate(spec, scene).H)
    path, _ = _patch_quadrature(scene)
    first = int(bin_index(path.min(), 0.0, scene.time.bin_width)) - 1
    hidden = H[:, first:].sum()
    assert H.sum() > 0, f"{spec.qualified_name}: the plate itself must be visible"
    assert hidden <= 1e-6 * H.sum(), (
        f"{spec.qualified_name} (confocal={confocal}): {hidden / H.sum():.3g} of the energy "
        "arrives from a patch that the plate hides from the laser and every sensor (no "
        "visibility test?)")


@requires(Capability.MESH_FILES, any_of=GEOMETRIES)
def check_mesh_file_matches_patch(spec: PluginSpec, confocal: bool) -> None:
    """A mesh file (OBJ, two triangles) of the 4 cm patch has the patch's analytic energy,
    in total and per sensor, within 5%."""
    h = 0.02
    obj = (f"v {-h} {-h} 0\nv {-h} {h} 0\nv {h} {h} 0\nv {h} {-h} 0\n"
           "f 1 2 3\nf 1 3 4\n")
    config = fixtures.tiny_scene_config(confocal=confocal, bins=400, patch=2 * h)
    patch = scene_from_config(config)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "patch.obj"
        path.write_text(obj)
        config["geometry"] = [{"type": "mesh", "path": str(path),
                               "position": list(fixtures.TINY_TARGET)}]
        H = _profiles(_simulate(spec, scene_from_config(config)).H)
    expected = _patch_quadrature(patch)[1].sum(axis=0)
    got = H.sum(axis=1)
    total = got.sum() / expected.sum()
    assert abs(total - 1) < ENERGY_RTOL, (
        f"{spec.qualified_name} (confocal={confocal}): a mesh file of the patch gives "
        f"{total:.4f} x the patch's analytic energy")
    ratio = got / expected
    worst = int(np.argmax(np.abs(ratio - 1)))
    assert np.all(np.abs(ratio - 1) < ENERGY_RTOL), (
        f"{spec.qualified_name} (confocal={confocal}): with the mesh file, sensor {worst} has "
        f"{ratio[worst]:.4f} x the patch's analytic energy")


@requires(any_of=GEOMETRIES)
def check_bad_scene_rejected(spec: PluginSpec, confocal: bool) -> None:
    """Geometry behind the wall or a time window without paths: a one-line ConfigError."""
    cases = {
        "scene.geometry[0]": fixtures.tiny_scene_config(target=(0.0, 0.0, -0.2),
                                                        confocal=confocal),
        "scene.time": {**fixtures.tiny_scene_config(confocal=confocal),
                       "time": {"bins": 64, "bin_width": 0.01, "start": 10.0}},
    }
    simulator = spec.create(dict(spec.test_config))
    for option, config in cases.items():
        text = one_line_error(spec, f"a scene with a bad {option}",
                              partial(_simulate_config, simulator, config),
                              ConfigError)
        assert option in text, (
            f"{spec.qualified_name}: expected one line naming {option}, got {text!r}")


SIMULATOR_CHECKS = (
    check_capture_layout,
    check_onset_matches_path_length,
    check_absolute_energy,
    check_energy_falloff,
    check_occlusion,
    check_mesh_file_matches_patch,
    check_bad_scene_rejected,
)


def _simulate_config(simulator: Simulator, config: Mapping[str, object]) -> Capture:
    """Simulate the scene of a plain config mapping (validated on the way)."""
    return simulator.simulate(scene_from_config(config))

"""The embree simulator against physics: closed forms, quadrature, independent visibility."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.common import ConfigError
from nlosfw.simulate import (
    AnalyticSimulator,
    bin_index,
    builtin_scene,
    scene_from_config,
    three_bounce,
)
from nlosfw.testing import (
    analytic_agreement,
    relative_l2,
    rendered,
    scene_with,
    tiny_scene_config,
)

pytest.importorskip("embreex")

from nlosfw_embree.simulator import EmbreeSimulator

TILTED = [{"type": "rectangle", "position": [0.1, -0.05, 0.6], "size": [0.3, 0.2],
           "rotation": [10.0, -20.0, 5.0], "albedo": 0.7}]


@pytest.mark.parametrize("capture", [{}, {"type": "confocal"}, {"device_legs": True},
                                     {"type": "confocal", "device_legs": True}],
                         ids=["single", "confocal", "legs", "confocal-legs"])
def test_agrees_with_analytic_in_absolute_value(capture):
    """Occlusion-free scene: same radiometric convention, same bins, same grid order."""
    scene = scene_with(TILTED, **capture)
    agree = analytic_agreement(EmbreeSimulator({"samples": 1 << 16}), scene)
    assert agree.total == pytest.approx(1.0, abs=0.003)
    assert agree.worst_sensor < 0.01
    assert agree.relative_l2 < 0.02


def test_shadowing_matches_independent_visibility():
    """Two parallel plates, the front one hiding part of the back one.

    The reference integrates both plates by quadrature and decides visibility of
    each leg by intersecting it with the other plate's plane, without Embree.
    """
    plates = [((-0.05, 0.02, 0.45), (0.3, 0.25)), ((0.08, -0.04, 0.75), (0.5, 0.4))]
    geometry = [{"type": "rectangle", "position": list(c), "size": list(s)} for c, s in plates]
    scene = scene_with(geometry, bins=320)
    sensors = scene.wall.grid_xyz().reshape(-1, 3)
    laser = scene.laser_spot_xyz()
    ref = np.zeros((sensors.shape[0], scene.time.bins + 1))
    n = 160
    for k, (centre, size) in enumerate(plates):
        u = (np.arange(n) + 0.5) / n - 0.5
        gx, gy = np.meshgrid(u * size[0], u * size[1], indexing="ij")
        pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1) + centre
        path, weight = three_bounce(laser, pts, np.tile([0, 0, -1.0], (pts.shape[0], 1)),
                                    np.full(pts.shape[0], size[0] * size[1] / pts.shape[0]),
                                    sensors)
        for j, (oc, osz) in enumerate(plates):
            if j == k or oc[2] >= centre[2]:
                continue
            t = oc[2] / pts[:, 2]                                    # plane z = oc[2]

            def blocked(wall_pts, t=t, oc=oc, osz=osz, pts=pts):
                hit = wall_pts[None, :, :2] + t[:, None, None] * (pts[:, None, :2]
                                                                  - wall_pts[None, :, :2])
                return ((np.abs(hit[..., 0] - oc[0]) < osz[0] / 2)
                        & (np.abs(hit[..., 1] - oc[1]) < osz[1] / 2))

            weight = weight * ~blocked(sensors) * ~blocked(laser[None])
        idx = np.clip(bin_index(path, 0.0, scene.time.bin_width), 0, scene.time.bins)
        for s in range(sensors.shape[0]):
            ref[s] += np.bincount(idx[:, s], weight[:, s], minlength=scene.time.bins + 1)
    ref = ref[:, :-1].reshape(scene.wall.resolution + (scene.time.bins,))
    ref = np.moveaxis(ref, -1, 0)
    capture = rendered(EmbreeSimulator({"samples": 1 << 17}), scene)
    unshadowed = rendered(AnalyticSimulator({"patch_size": 0.004}), scene).H.sum()
    assert ref.sum() < 0.97 * unshadowed                       # the shadow matters here
    assert capture.H.sum() / ref.sum() == pytest.approx(1.0, abs=0.005)
    assert relative_l2(capture.H, ref) < 0.03
    assert capture.scene_info["render"]["unobstructed_fraction"] < 0.99


def test_point_scatterers_are_exact_and_can_be_hidden():
    visible = {"type": "point", "position": [0.2, 0.1, 0.7], "albedo": 0.01}
    hidden = {"type": "point", "position": [-0.05, 0.0, 1.2], "albedo": 0.01}
    plate = {"type": "rectangle", "position": [-0.05, 0.0, 0.3], "size": [1.2, 1.2]}
    scene = scene_with([visible], bins=400)
    exact = rendered(AnalyticSimulator(), scene).H
    np.testing.assert_allclose(rendered(EmbreeSimulator(), scene).H, exact, rtol=1e-5,
                               atol=1e-6 * exact.max())
    both = rendered(EmbreeSimulator({"samples": 4096}),
                    scene_with([hidden, plate], bins=400)).H
    plate_only = rendered(EmbreeSimulator({"samples": 4096}), scene_with([plate], bins=400)).H
    np.testing.assert_array_equal(both, plate_only)


def test_closed_box_renders_as_its_front_face():
    """With the laser spot in front of it, only a box's wall-facing face is lit."""
    box = {"type": "box", "position": [0.05, 0.0, 0.701], "size": [0.3, 0.3, 0.002]}
    face = {"type": "rectangle", "position": [0.05, 0.0, 0.7], "size": [0.3, 0.3]}
    H = rendered(EmbreeSimulator({"samples": 1 << 16}), scene_with([box])).H
    reference = rendered(AnalyticSimulator({"patch_size": 0.003}), scene_with([face])).H
    assert H.sum() / reference.sum() == pytest.approx(1.0, abs=0.01)
    assert relative_l2(H, reference) < 0.04


def test_mesh_file_renders_like_the_same_rectangle(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    w, h = 0.3, 0.2
    verts = np.array([[-w / 2, -h / 2, 0], [-w / 2, h / 2, 0], [w / 2, h / 2, 0],
                      [w / 2, -h / 2, 0]])
    trimesh.Trimesh(verts, [[0, 1, 2], [0, 2, 3]]).export(tmp_path / "plate.obj")
    common = {"position": [0.1, -0.05, 0.6], "rotation": [0.0, 15.0, 0.0]}
    mesh = scene_with([{"type": "mesh", "path": str(tmp_path / "plate.obj"), **common}])
    rect = scene_with([{"type": "rectangle", "size": [w, h], **common}])
    H = EmbreeSimulator({"samples": 1 << 15}).simulate(mesh).H
    reference = rendered(AnalyticSimulator({"patch_size": 0.003}), rect).H
    assert H.sum() / reference.sum() == pytest.approx(1.0, abs=0.005)
    (tmp_path / "empty.obj").write_text("")
    for bad in ("missing.obj", "empty.obj"):
        broken = scene_with([{"type": "mesh", "path": str(tmp_path / bad)}])
        with pytest.raises(ConfigError, match=r"scene\.geometry\[0\]\.path"):
            EmbreeSimulator().simulate(broken)


def test_deterministic_independent_of_threads_and_seeded():
    scene = builtin_scene("thesis_occluded", wall={"resolution": [8, 8]},
                          time={"bins": 256, "bin_width": 0.024})
    one = rendered(EmbreeSimulator({"samples": 5000, "threads": 1, "batch": 512}), scene).H
    two = rendered(EmbreeSimulator({"samples": 5000, "threads": 2, "batch": 512}), scene).H
    np.testing.assert_array_equal(one, two)
    other = rendered(EmbreeSimulator({"samples": 5000, "seed": 1, "batch": 512}), scene).H
    assert not np.array_equal(one, other)
    assert other.sum() / one.sum() == pytest.approx(1.0, abs=0.02)


def test_sobol_sampling_is_unbiased_and_beats_independent_sampling():
    scene = scene_with(TILTED)
    reference = rendered(AnalyticSimulator({"patch_size": 0.003}), scene).H
    errors = {}
    for sampler in ("sobol", "independent"):
        runs = [rendered(EmbreeSimulator({"samples": 4096, "sampler": sampler, "seed": s}), scene).H
                for s in range(4)]
        mean = np.mean(runs, axis=0)
        assert mean.sum() / reference.sum() == pytest.approx(1.0, abs=0.01)
        errors[sampler] = np.mean([relative_l2(h, reference) for h in runs])
    assert errors["sobol"] < 0.7 * errors["independent"]


def test_ray_statistics_report_occlusion():
    small = {"wall": {"resolution": [8, 8]}, "time": {"bins": 256, "bin_width": 0.024}}
    free = rendered(EmbreeSimulator({"samples": 2000}), builtin_scene("thesis_two_planes", **small))
    stats = free.scene_info["render"]
    assert stats["unobstructed_fraction"] == 1.0          # the scene is occlusion-free
    assert stats["rays"] == 2000 * 64 + 2000              # sensor legs + laser legs
    shadowed = rendered(EmbreeSimulator({"samples": 2000}),
                        builtin_scene("thesis_occluded", **small))
    assert shadowed.scene_info["render"]["unobstructed_fraction"] < 0.98


def test_window_start_and_cut():
    """A window starting mid-way records the same later bins as a full window."""
    full = scene_with(TILTED, bins=300)
    late_config = tiny_scene_config(bins=150, bin_width=0.01)
    late_config["wall"]["resolution"] = [12, 10]
    late_config["geometry"] = TILTED
    late_config["time"]["start"] = 1.5
    late = scene_from_config(late_config)
    a = rendered(EmbreeSimulator({"samples": 1 << 14}), full).H.astype(float)
    b = rendered(EmbreeSimulator({"samples": 1 << 14}), late).H.astype(float)
    assert b.sum() / a[150:].sum() == pytest.approx(1.0, abs=1e-5)
    # float32 bin arithmetic may move a path lying within ~1e-4 bins of an edge
    moved = np.abs(b - a[150:]) > 1e-4 * a.max()
    assert moved.mean() < 0.005


def test_a_glossy_item_is_refused_naming_its_lobe():
    """Embree renders the Lambertian convention only: an item with a lobe is refused in
    one line before rendering, naming the item and the simulator that renders lobes."""
    config = tiny_scene_config()
    config["geometry"][0]["lobe"] = 4.0
    with pytest.raises(ConfigError, match="Lambertian surfaces only.*analytic") as err:
        EmbreeSimulator({}).check(scene_from_config(config))
    assert err.value.option == "scene.geometry[0].lobe"

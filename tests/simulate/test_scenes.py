"""The built-in scenes (conf/scene/*.yaml) and the scene config group."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from nlosfw.common.config import config_to_dict
from nlosfw.common.errors import ConfigError
from nlosfw.common.resources import config_dir
from nlosfw.simulate.builtin_scenes import builtin_scene, builtin_scene_config, builtin_scene_names
from nlosfw.simulate.geometry import sample_surface, validate_scene
from nlosfw.simulate.scene import Scene, scene_from_config
from nlosfw.simulate.visibility import ground_truth_maps

THESIS = ("thesis_planes", "thesis_concave", "thesis_two_planes", "thesis_occluded")
QUICK = ("plane", "letter_t", "point")


def test_every_required_scene_is_built_in():
    names = builtin_scene_names()
    for name in THESIS + QUICK:
        assert name in names


BLOCKS = ("wall", "capture", "time", "noise")


@pytest.mark.parametrize("name", builtin_scene_names())
def test_scene_files_hold_scene_fields_and_share_the_blocks(name):
    text = (config_dir() / "scene" / f"{name}.yaml").read_text()
    data = yaml.safe_load(text)
    fields = {f.name for f in dataclasses.fields(Scene)}
    assert set(data) - {"defaults"} <= fields
    assert data["defaults"] == [{"base@_here_": "default"}, "_self_"]
    if name != "tiny":
        assert not set(data) & set(BLOCKS), "a scene file copies a shared block"
    resolved = builtin_scene_config(name)
    assert {"name", "geometry", *BLOCKS} <= set(resolved) <= fields
    assert resolved["name"] == name


def compose_scene(*overrides):
    """``cfg.scene`` as the command line composes it (Hydra's compose API)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf

    from nlosfw.common.resources import config_dir
    from nlosfw.compose import ensure_resolvers, register_configs
    from nlosfw.plugins import load_plugins

    register_configs(load_plugins())
    ensure_resolvers()
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
            cfg = compose(config_name="config", overrides=list(overrides))
    finally:
        GlobalHydra.instance().clear()
    return OmegaConf.to_container(cfg, resolve=True)["scene"]


@pytest.mark.parametrize("name", builtin_scene_names())
def test_hydra_composes_the_scenes_builtin_scene_reads(name):
    """The command line (Hydra's defaults list) and builtin_scene build the same scene."""
    composed = scene_from_config(compose_scene(f"scene={name}"))
    assert composed == builtin_scene(name)


@pytest.mark.parametrize("name", THESIS + QUICK)
def test_defaults_and_time_window_hold_every_path(name):
    scene = builtin_scene(name)
    assert scene.wall.size == (2.0, 2.0) and scene.wall.resolution == (64, 64)
    assert scene.wall.center == (0.0, 0.0)
    assert scene.capture.type == "single_spot" and scene.capture.laser_spot == (0.0, 0.0)
    assert (scene.time.bins, scene.time.bin_width, scene.time.start) == (2048, 0.003, 0.0)
    lo, hi = validate_scene(scene).path_range
    assert scene.time.start <= lo and hi < scene.time.end


def test_unknown_scene_lists_the_valid_names():
    with pytest.raises(ConfigError) as err:
        builtin_scene("thesis_nope")
    text = str(err.value)
    assert text.startswith("scene: unknown scene 'thesis_nope'; valid: ")
    assert "thesis_two_planes" in text and "\n" not in text


def test_overrides_merge_into_the_scene():
    scene = builtin_scene("plane", wall={"resolution": [8, 4]}, time={"bins": 512},
                          capture={"type": "confocal"})
    assert scene.wall.resolution == (8, 4) and scene.wall.size == (2.0, 2.0)
    assert scene.time.bins == 512 and scene.time.bin_width == 0.003
    assert scene.is_confocal
    with pytest.raises(ConfigError, match=r"wall\.colour"):
        builtin_scene("plane", wall={"colour": 1})


def _blocked_fraction(name: str) -> float:
    """Fraction of (wall point, surface point) segments crossing another item (no Embree).

    Every item of these scenes is an unrotated rectangle facing the wall, so a
    segment crosses item j exactly when it meets the plane of j inside j.
    """
    scene = builtin_scene(name, wall={"resolution": [9, 9]})
    items = scene.geometry
    wall = np.concatenate([scene.wall.grid_xyz().reshape(-1, 3), scene.laser_spot_xyz()[None]])
    blocked = total = 0
    for k, item in enumerate(items):
        w, h = item.size
        u = np.random.default_rng(k).random((400, 2)) - 0.5
        p = np.asarray(item.position) + np.c_[u[:, 0] * w, u[:, 1] * h, np.zeros(400)]
        hit = np.zeros((p.shape[0], wall.shape[0]), bool)
        for j, other in enumerate(items):
            z = other.position[2]
            if j == k or z >= item.position[2]:
                continue
            t = z / p[:, 2]
            q = wall[None, :, :2] + t[:, None, None] * (p[:, None, :2] - wall[None, :, :2])
            hit |= ((np.abs(q[..., 0] - other.position[0]) < other.size[0] / 2)
                    & (np.abs(q[..., 1] - other.position[1]) < other.size[1] / 2))
        blocked, total = blocked + hit.sum(), total + hit.size
    return blocked / total


def test_two_planes_is_occlusion_free_and_occluded_is_not():
    assert _blocked_fraction("thesis_two_planes") == 0.0
    assert _blocked_fraction("thesis_occluded") > 0.05
    two = builtin_scene("thesis_two_planes")
    assert len(two.geometry) == 2 and two.geometry[0].position[2] != two.geometry[1].position[2]


def test_occluded_ground_truth_shows_the_front_plane_over_the_back_one():
    scene = builtin_scene("thesis_occluded", wall={"resolution": [32, 32]})
    geometry = validate_scene(scene)
    depth, _ = ground_truth_maps(geometry.mesh, scene.wall.grid_xyz())
    front, back = (item.position[2] for item in scene.geometry)
    assert np.isclose(depth, front).sum() > 50 and np.isclose(depth, back).sum() > 50
    # the back plane's footprint is partly covered by the front plane
    x, y = scene.wall.grid_xyz()[..., 0], scene.wall.grid_xyz()[..., 1]
    b = scene.geometry[1]
    under_back = (np.abs(x - b.position[0]) < b.size[0] / 2) & (np.abs(y - b.position[1])
                                                                < b.size[1] / 2)
    assert np.isclose(depth[under_back], front).any()


def test_thesis_planes_are_one_depth_with_fine_detail():
    scene = builtin_scene("thesis_planes")
    depths = {item.position[2] for item in scene.geometry}
    sizes = sorted(min(item.size) for item in scene.geometry)
    assert len(depths) == 1 and len(scene.geometry) >= 6
    assert sizes[0] <= 0.04 and sizes[-1] >= 0.3       # from sub-grid detail to large planes


def test_thesis_concave_has_concavities_and_spikes():
    scene = builtin_scene("thesis_concave")
    geometry = validate_scene(scene)
    base = scene.geometry[0].position[2]
    z = geometry.mesh.vertices[:, 2]
    assert z.min() < base - 0.1 and z.max() > base + 0.1
    points, normals, _, _ = sample_surface(geometry.mesh, 2000, np.random.default_rng(0))
    assert np.mean(np.abs(normals[:, 2]) < 0.7) > 0.05        # steep flanks that cast shadows


def test_bad_time_axis_is_refused_with_one_line():
    for time, option in (({"bins": 0}, "bins"), ({"bins": -5}, "bins"),
                         ({"bin_width": 0.0}, "bin_width"), ({"bin_width": -0.003}, "bin_width")):
        with pytest.raises(ConfigError, match=rf"^scene\.time\.{option}: must be a positive") as e:
            builtin_scene("plane", time=time)
        assert "\n" not in str(e.value)


def test_scene_base_lists_every_option_and_each_can_be_overridden():
    """The shared base documents every option of its blocks, and the command line can
    override every option of a scene (the run's schema types ``scene`` as a Scene)."""
    def fields(cls):
        return {f.name: f for f in dataclasses.fields(cls)}

    base = yaml.safe_load((config_dir() / "scene" / "base" / "default.yaml").read_text())
    assert set(base) == set(BLOCKS)
    for block in BLOCKS:
        assert set(base[block]) == set(fields(fields(Scene)[block].default_factory)), block
    scene = scene_from_config(compose_scene(
        "scene=plane", "scene.wall.center=[0.1,0.2]", "scene.capture.type=confocal",
        "scene.capture.device_legs=true", "scene.time.start=0.5", "scene.noise.model=poisson",
        "scene.noise.jitter_ps=20", "scene.ground_truth_resolution=[8,8]",
        "scene.geometry.0.rotation=[0,10,0]"))
    assert scene.wall.center == (0.1, 0.2) and scene.is_confocal and scene.capture.device_legs
    assert scene.time.start == 0.5 and scene.ground_truth_resolution == (8, 8)
    assert scene.noise.model == "poisson" and scene.noise.jitter_ps == 20.0
    assert scene.geometry[0].rotation == (0.0, 10.0, 0.0) and scene.geometry[0].size == (0.6, 0.6)


def test_params_are_refused_where_they_would_be_ignored():
    from nlosfw.common.errors import ConfigError
    from nlosfw.simulate.scene import GeometryItem

    with pytest.raises(ConfigError, match="params: only heightfield items take params"):
        GeometryItem(type="rectangle", params={"bumps": []})


@pytest.mark.parametrize("name", builtin_scene_names())
def test_builtin_scenes_are_unchanged(name):
    """Every built-in scene equals the one recorded in tests/data/builtin_scenes.json.

    The file holds ``config_to_dict(builtin_scene(name))`` of every scene as written by
    commit 343f1f1, when each YAML file still spelled out all of its blocks (with the
    options added since at their defaults: ``noise.pulses`` null, each item's ``lobe`` 0);
    it guards the scenes against changes in how their files share those blocks.
    """
    data = Path(__file__).resolve().parents[1] / "data"
    recorded = json.loads((data / "builtin_scenes.json").read_text())
    assert sorted(recorded) == builtin_scene_names()
    scene = builtin_scene(name)
    assert config_to_dict(scene) == recorded[name]
    assert isinstance(scene.geometry, tuple) and isinstance(scene.wall.resolution, tuple)
    assert all(isinstance(item.position, tuple) for item in scene.geometry)

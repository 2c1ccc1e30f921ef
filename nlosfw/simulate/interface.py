"""The simulator interface: a scene in, a transient capture out."""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, TypeVar

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import GridFormat, HFormat
from nlosfw.common.config import Configurable, config_to_dict, require_seed
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.simulate.geometry import SceneGeometry
from nlosfw.simulate.scene import Scene


@dataclass(frozen=True)
class SimulatorConfig:
    """Options shared by every simulator."""

    seed: int = 0
    """Seed of every random choice (sampling and noise): same seed, same capture."""

    def __post_init__(self) -> None:
        require_seed(self.seed, "seed")


SimulatorConfigT = TypeVar("SimulatorConfigT", bound=SimulatorConfig)


class Simulator(Configurable[SimulatorConfigT], ABC):
    """Renders a :class:`~nlosfw.simulate.Scene` into a transient :class:`Capture`.

    Subclasses implement :meth:`render` (noise-free transport of a validated
    scene) and may refuse scenes in :meth:`check_scene`. :meth:`simulate` adds
    what every simulator shares: validation, ground truth, metadata, noise.
    """

    config_class: ClassVar[type] = SimulatorConfig
    renders_lobes: ClassVar[bool] = False
    """Whether :meth:`render` follows an item's ``lobe`` (else a glossy item is refused)."""

    @abstractmethod
    def render(self, geometry: SceneGeometry) -> Capture:
        """Noise-free transient of ``geometry.scene`` in the layout of :func:`scene_capture`.

        ``geometry`` is the scene validated by :func:`nlosfw.simulate.geometry.validate_scene`
        with its triangles and point scatterers built once; use them rather than
        rebuilding meshes. :meth:`check_scene` has already accepted the scene.
        """

    def check_scene(self, scene: Scene) -> None:
        """Raise a one-line ConfigError if this simulator cannot render ``scene``.

        Cheap checks only (no rendering): the command line calls it before any
        output exists, and :meth:`simulate` calls it before rendering. The
        default accepts every valid scene.
        """

    def check(self, scene: Scene) -> None:
        """Every check of ``scene`` for this simulator: a glossy item (``lobe`` > 0) is
        refused unless it :attr:`renders_lobes`, then :meth:`check_scene`."""
        if not self.renders_lobes:
            for i, item in enumerate(scene.geometry):
                if item.lobe > 0:
                    raise ConfigError(f"scene.geometry[{i}].lobe", (
                        f"{type(self).__name__} renders Lambertian surfaces only; valid: 0, "
                        "or a simulator that renders lobes (analytic)"))
        self.check_scene(scene)

    def simulate(self, scene: Scene, base_dir: Path | None = None) -> Capture:
        """The capture of ``scene``: rendered, with ground truth and metadata, then noise."""
        return self.add_noise(self.simulate_clean(scene, base_dir), scene)

    def simulate_clean(self, scene: Scene, base_dir: Path | None = None) -> Capture:
        """The noise-free capture of ``scene`` with ground truth and metadata.

        Relative mesh paths resolve against ``base_dir`` (default: the working
        directory). ``scene_info['scene']`` records the scene without its noise.
        """

        from nlosfw.simulate.geometry import validate_scene
        from nlosfw.simulate.scene import NoiseConfig
        from nlosfw.simulate.visibility import ground_truth_maps

        geometry = validate_scene(scene, base_dir)  # one-line ConfigError for a bad scene
        scene = geometry.scene
        self.check(scene)
        capture = self.render(geometry)
        expected = (scene.time.bins,) + _sensor_axes(scene)
        if capture.H.shape != expected:
            raise DataError(f"{type(self).__name__}.render returned H of shape {capture.H.shape}, "
                            f"expected {expected}")
        res = scene.ground_truth_resolution or scene.wall.resolution
        gt_wall = type(scene.wall)(size=scene.wall.size, resolution=(int(res[0]), int(res[1])),
                                   center=scene.wall.center)
        depth, albedo = ground_truth_maps(geometry.mesh, gt_wall.grid_xyz())
        info = dict(capture.scene_info)
        info.update({
            "original_format": "nlosfw",
            "scene": config_to_dict(dataclasses.replace(scene, noise=NoiseConfig())),
            "simulator": {"class": type(self).__name__, "config": config_to_dict(self.config)},
            "noise": {"model": "none"},
            "ground_truth": {
                "format": "X_Y",
                "depth": np.round(depth, 6).tolist(),
                "albedo": np.round(albedo, 6).tolist(),
            },
        })
        return capture.replace(H=np.asarray(capture.H, dtype=np.float32), scene_info=info)

    def add_noise(self, capture: Capture, scene: Scene) -> Capture:
        """``capture`` (from :meth:`simulate_clean`) with ``scene``'s noise, drawn from the seed.

        Returns ``capture`` itself when the scene has no noise.
        """
        from nlosfw.simulate.noise import apply_noise

        if scene.noise.model == "none" and scene.noise.jitter_ps <= 0:
            return capture
        rng = np.random.default_rng([self.config.seed, 0x6E6F697365])  # "noise" stream
        H, noise_info = apply_noise(capture.H, capture.delta_t, scene.noise, rng)
        info = {**capture.scene_info, "noise": noise_info,
                "scene": {**capture.scene_info.get("scene", {}),
                          "noise": config_to_dict(scene.noise)}}
        return capture.replace(H=np.asarray(H, dtype=np.float32), scene_info=info)


def _sensor_axes(scene: Scene) -> tuple[int, int]:
    return (scene.wall.resolution[0], scene.wall.resolution[1])


def scene_capture(scene: Scene, H: np.ndarray) -> Capture:
    """Wrap a histogram ``H`` (T, X, Y) rendered from ``scene`` in the standard capture layout.

    Every simulator builds its output with this so that captures from different
    simulators agree in grids, normals, formats and time axis.
    """
    grid = scene.wall.grid_xyz()
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), grid.shape).copy()
    if scene.is_confocal:
        laser_grid, laser_normals = grid, normals
    else:
        laser_grid = scene.laser_spot_xyz().reshape(1, 1, 3)
        laser_normals = np.array([0.0, 0.0, 1.0]).reshape(1, 1, 3)
    return Capture(
        H=np.asarray(H, dtype=np.float32),
        H_format=HFormat.T_Sx_Sy,
        sensor_grid_xyz=grid,
        sensor_grid_normals=normals,
        sensor_grid_format=GridFormat.X_Y_3,
        laser_grid_xyz=laser_grid,
        laser_grid_normals=laser_normals,
        laser_grid_format=GridFormat.X_Y_3,
        sensor_xyz=np.asarray(scene.capture.sensor_position, dtype=float),
        laser_xyz=np.asarray(scene.capture.laser_position, dtype=float),
        delta_t=scene.time.bin_width,
        t_start=scene.time.start,
        t_accounts_first_and_last_bounces=scene.capture.device_legs,
    )

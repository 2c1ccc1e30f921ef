"""The four pluggable interfaces and their base configuration dataclasses.

Plugins subclass one of :class:`Simulator`, :class:`PhasorTransform`,
:class:`FieldModel`, :class:`Imager`, set ``config_class`` to a frozen
dataclass deriving from the matching ``*Config`` base, and exchange only numpy
arrays and the core data types (:class:`~nlosfw.capture.Capture`,
:class:`~nlosfw.phasor_field.PhasorField`,
:class:`~nlosfw.reconstruction.Reconstruction`).
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlosfw.capture import Capture, CaptureGeometry
from nlosfw.config import config_from_mapping, config_to_dict, require
from nlosfw.enums import GridFormat, HFormat
from nlosfw.errors import DataError
from nlosfw.geometry import SceneGeometry
from nlosfw.phasor_field import PhasorField
from nlosfw.reconstruction import Reconstruction
from nlosfw.scene import Scene

log = logging.getLogger(__name__)


class _Configurable:
    """Holds a validated, immutable config instance of ``config_class``."""

    config_class: ClassVar[type] = object

    def __init__(self, config: Any = None) -> None:
        self.config = config_from_mapping(self.config_class, config)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({config_to_dict(self.config)})"


# --------------------------------------------------------------------------- simulators
@dataclass(frozen=True)
class SimulatorConfig:
    """Options shared by every simulator."""

    seed: int = 0
    """Seed of every random choice (sampling and noise): same seed, same capture."""


class Simulator(_Configurable, ABC):
    """Renders a :class:`~nlosfw.scene.Scene` into a transient :class:`Capture`.

    Subclasses implement :meth:`render` (noise-free transport of a validated
    scene) and may refuse scenes in :meth:`check_scene`. :meth:`simulate` adds
    what every simulator shares: validation, ground truth, metadata, noise.
    """

    config_class: ClassVar[type] = SimulatorConfig

    @abstractmethod
    def render(self, geometry: SceneGeometry) -> Capture:
        """Noise-free transient of ``geometry.scene`` in the layout of :func:`scene_capture`.

        ``geometry`` is the scene validated by :func:`nlosfw.geometry.validate_scene`
        with its triangles and point scatterers built once; use them rather than
        rebuilding meshes. :meth:`check_scene` has already accepted the scene.
        """

    def check_scene(self, scene: Scene) -> None:
        """Raise a one-line ConfigError if this simulator cannot render ``scene``.

        Cheap checks only (no rendering): the command line calls it before any
        output exists, and :meth:`simulate` calls it before rendering. The
        default accepts every valid scene.
        """

    def simulate(self, scene: Scene, base_dir: Path | None = None) -> Capture:
        """The capture of ``scene``: rendered, with ground truth and metadata, then noise."""
        return self.add_noise(self.simulate_clean(scene, base_dir), scene)

    def simulate_clean(self, scene: Scene, base_dir: Path | None = None) -> Capture:
        """The noise-free capture of ``scene`` with ground truth and metadata.

        Relative mesh paths resolve against ``base_dir`` (default: the working
        directory). ``scene_info['scene']`` records the scene without its noise.
        """
        import dataclasses

        from nlosfw.geometry import ground_truth_maps, validate_scene
        from nlosfw.scene import NoiseConfig

        geometry = validate_scene(scene, base_dir)  # one-line ConfigError for a bad scene
        scene = geometry.scene
        self.check_scene(scene)
        capture = self.render(geometry)
        expected = (scene.time.bins,) + _sensor_axes(scene)
        if capture.H.shape != expected:
            raise DataError(f"{type(self).__name__}.render returned H of shape {capture.H.shape}, "
                            f"expected {expected}")
        res = scene.ground_truth_resolution or scene.wall.resolution
        gt_wall = type(scene.wall)(size=scene.wall.size, resolution=tuple(res),
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
        from nlosfw.noise import apply_noise

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


# --------------------------------------------------------------------------- transforms
@dataclass(frozen=True)
class PhasorTransformConfig:
    """Options shared by every phasor transform (none yet)."""


class PhasorTransform(_Configurable, ABC):
    """Turns a time-domain :class:`Capture` into a :class:`PhasorField`."""

    config_class: ClassVar[type] = PhasorTransformConfig

    @abstractmethod
    def transform(self, capture: Capture) -> PhasorField:
        """The phasor field of ``capture`` at this transform's frequencies."""


# --------------------------------------------------------------------------- field models
@dataclass(frozen=True)
class FieldModelConfig:
    """Options shared by every field model."""

    seed: int = 0
    """Seed of initialisation and batching: same seed and data, same model (on CPU)."""
    device: str = "auto"
    """Where to train: ``auto`` (a GPU when present), ``cpu``, or a backend device name."""

    def __post_init__(self) -> None:
        require(bool(self.device), "device", "must be auto, cpu or a device name")


@dataclass(frozen=True)
class TrainingStep:
    """Progress of a fit, reported to ``on_step`` callbacks."""

    step: int
    total_steps: int
    loss: float
    val_loss: float | None = None
    seconds: float = 0.0


@dataclass
class FitReport:
    """What happened during :meth:`FieldModel.fit`."""

    steps: int
    seconds: float
    final_loss: float
    best_val_loss: float | None = None
    stopped_early: bool = False
    history: list[dict[str, float]] = field(default_factory=list)


class FieldModel(_Configurable, ABC):
    """A continuous representation F(x, y, omega) -> P fitted to a discrete phasor field."""

    config_class: ClassVar[type] = FieldModelConfig

    @abstractmethod
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Fit to ``field``; ``validation`` (if given) drives early stopping."""

    @abstractmethod
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Complex field at wall points ``wall_xy`` (..., 2) and ``frequencies`` (F,).

        Returns shape (F, ...). Works after :meth:`fit` or :meth:`load` only.
        """

    @property
    @abstractmethod
    def n_parameters(self) -> int:
        """Number of trainable parameters (or stored values for non-neural models)."""

    @abstractmethod
    def save(self, path: str | Path) -> None:
        """Write weights, config and normalisation to one file."""

    @classmethod
    @abstractmethod
    def load(cls, path: str | Path) -> FieldModel:
        """Read a file written by :meth:`save` of the same model class."""

    def predict_field(self, wall_xyz: np.ndarray, frequencies: np.ndarray,
                      geometry: CaptureGeometry, weights: np.ndarray | None = None,
                      metadata: Mapping[str, Any] | None = None) -> PhasorField:
        """The model evaluated on a wall grid ``wall_xyz`` (Y, X, 3) as a :class:`PhasorField`."""
        wall_xyz = np.asarray(wall_xyz, dtype=float)
        values = self.predict(wall_xyz[..., :2], np.asarray(frequencies, dtype=float))
        return PhasorField(values=values, frequencies=frequencies, wall_xyz=wall_xyz,
                           geometry=geometry, weights=weights, metadata=dict(metadata or {}))


# --------------------------------------------------------------------------- imagers
@dataclass(frozen=True)
class ImagerConfig:
    """Options shared by every imager (none yet)."""


class Imager(_Configurable, ABC):
    """Propagates a :class:`PhasorField` into the hidden volume and images it."""

    config_class: ClassVar[type] = ImagerConfig

    @abstractmethod
    def reconstruct(self, field: PhasorField, voxels: np.ndarray) -> Reconstruction:
        """Intensity at ``voxels``: a plane (Y, X, 3), planes (Z, Y, X, 3) or points (N, 3)."""


#: The interface class of each plugin kind (by :class:`~nlosfw.enums.PluginKind` value).
INTERFACES: dict[str, type] = {
    "simulator": Simulator,
    "transform": PhasorTransform,
    "model": FieldModel,
    "imager": Imager,
}

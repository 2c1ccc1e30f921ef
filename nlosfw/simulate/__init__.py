"""Stage 1 (simulated): scenes, their geometry, light transport and the Simulator interface.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.simulate.analytic import AnalyticConfig, AnalyticSimulator
    from nlosfw.simulate.builtin_scenes import (
        builtin_scene,
        builtin_scene_config,
        builtin_scene_names,
        merge_config,
    )
    from nlosfw.simulate.geometry import (
        PointScatterers,
        SceneGeometry,
        TriangleMesh,
        item_mesh,
        path_length_range,
        resolve_mesh_paths,
        rotation_matrix,
        sample_surface,
        scene_mesh,
        scene_points,
        sobol_engine,
        surface_points,
        unit_square_samples,
        validate_scene,
    )
    from nlosfw.simulate.interface import Simulator, SimulatorConfig, scene_capture
    from nlosfw.simulate.noise import apply_noise
    from nlosfw.simulate.physics import bin_index, three_bounce
    from nlosfw.simulate.scene import (
        GEOMETRY_TYPES,
        CaptureSetup,
        GeometryItem,
        NoiseConfig,
        Scene,
        TimeAxis,
        WallConfig,
        scene_from_config,
    )
    from nlosfw.simulate.visibility import blocked_fraction, ground_truth_maps

__all__ = [
    "AnalyticConfig",
    "AnalyticSimulator",
    "apply_noise",
    "bin_index",
    "blocked_fraction",
    "builtin_scene",
    "builtin_scene_config",
    "builtin_scene_names",
    "CaptureSetup",
    "GEOMETRY_TYPES",
    "GeometryItem",
    "ground_truth_maps",
    "item_mesh",
    "merge_config",
    "NoiseConfig",
    "path_length_range",
    "PointScatterers",
    "resolve_mesh_paths",
    "rotation_matrix",
    "sample_surface",
    "Scene",
    "scene_capture",
    "scene_from_config",
    "scene_mesh",
    "scene_points",
    "SceneGeometry",
    "Simulator",
    "SimulatorConfig",
    "sobol_engine",
    "surface_points",
    "three_bounce",
    "TimeAxis",
    "TriangleMesh",
    "unit_square_samples",
    "validate_scene",
    "WallConfig",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

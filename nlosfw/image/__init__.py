"""Stage 4, imaging: phasor fields propagated into the hidden volume (Rayleigh-Sommerfeld).

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these. The reconstruction scores this package exported before
(``psnr``, ``ssim``, ...) are :mod:`nlosfw.evaluation`'s now; they still load from here
for one minor version, with a :class:`DeprecationWarning` naming their new place."""


from typing import TYPE_CHECKING

from nlosfw.common.deprecation import moved_names
from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.common.progress import ProgressCallback
    from nlosfw.image.depths import automatic_depths, depth_span
    from nlosfw.image.fft import FFTImager, FFTImagerConfig
    from nlosfw.image.fk import FKImager
    from nlosfw.image.interface import Imager, ImagerConfig, ImagerNeeds
    from nlosfw.image.lct import (
        FBPImager,
        FBPImagerConfig,
        LCTImager,
        LCTImagerConfig,
        LightConeConfig,
    )
    from nlosfw.image.plane_convolution import GridLayout, grid_layout
    from nlosfw.image.propagation import PropagationConfig, PropagationImager
    from nlosfw.image.reconstruction import (
        Reconstruction,
        plane_voxels,
        volume_voxels,
        wall_voxels,
    )
    from nlosfw.image.reconstruction_io import read_reconstruction, write_reconstruction
    from nlosfw.image.rsd import RSDImager, RSDImagerConfig
    from nlosfw.image.rsd_kernel import (
        laser_phase,
        path_multiplier,
        phasor_steps,
        wall_field,
    )
    from nlosfw.image.transient import (
        TransientImager,
        TransientImagerConfig,
    )

__all__ = [
    "grid_layout",
    "GridLayout",
    "automatic_depths",
    "depth_span",
    "FBPImager",
    "FBPImagerConfig",
    "FFTImager",
    "FFTImagerConfig",
    "FKImager",
    "Imager",
    "ImagerNeeds",
    "ImagerConfig",
    "LCTImager",
    "LCTImagerConfig",
    "LightConeConfig",
    "laser_phase",
    "path_multiplier",
    "phasor_steps",
    "plane_voxels",
    "ProgressCallback",
    "PropagationConfig",
    "PropagationImager",
    "read_reconstruction",
    "Reconstruction",
    "RSDImager",
    "RSDImagerConfig",
    "TransientImager",
    "TransientImagerConfig",
    "volume_voxels",
    "wall_field",
    "wall_voxels",
    "write_reconstruction",
]

#: The scores this package exported before :mod:`nlosfw.evaluation` held them.
MOVED = {n: f"nlosfw.evaluation:{n}" for n in (
    "amplitude", "depth_rmse", "image_metrics", "normalise", "psnr", "reconstruction_scores",
    "rmse", "ssim")}

_lazy_getattr, __dir__ = lazy_exports(__name__, __file__)
__getattr__ = moved_names(__name__, MOVED, _lazy_getattr)

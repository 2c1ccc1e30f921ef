"""Stage 4, imaging: phasor fields propagated into the hidden volume (Rayleigh-Sommerfeld)
and scored.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from nlosfw.common.progress import ProgressCallback
from nlosfw.image.fft import FFTImager, FFTImagerConfig
from nlosfw.image.interface import Imager, ImagerConfig
from nlosfw.image.propagation import PropagationConfig, PropagationImager
from nlosfw.image.reconstruction import Reconstruction, cell_centres, plane_voxels, volume_voxels
from nlosfw.image.reconstruction_io import read_reconstruction, write_reconstruction
from nlosfw.image.rsd import RSDImager, RSDImagerConfig
from nlosfw.image.rsd_kernel import (
    kernel,
    laser_phase,
    path_multiplier,
    phasor_series,
    phasor_steps,
    wall_field,
)
from nlosfw.image.scores import image_metrics, normalise, psnr, rmse, ssim

__all__ = [
    "cell_centres",
    "FFTImager",
    "FFTImagerConfig",
    "image_metrics",
    "Imager",
    "ImagerConfig",
    "kernel",
    "laser_phase",
    "normalise",
    "path_multiplier",
    "phasor_series",
    "phasor_steps",
    "plane_voxels",
    "ProgressCallback",
    "PropagationConfig",
    "PropagationImager",
    "psnr",
    "read_reconstruction",
    "Reconstruction",
    "rmse",
    "RSDImager",
    "RSDImagerConfig",
    "ssim",
    "volume_voxels",
    "wall_field",
    "write_reconstruction",
]

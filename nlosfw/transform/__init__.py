"""Stage 2, the phasor transform: a transient capture becomes complex wall fields,
one per frequency.

The names in ``__all__`` are the public API of this stage: plugins, examples and docs
import only these."""


from typing import TYPE_CHECKING

from nlosfw.common.lazy import lazy_exports

if TYPE_CHECKING:  # at run time each name loads on first use (nlosfw.common.lazy)
    from nlosfw.transform.fft import FFTTransform, FFTTransformConfig
    from nlosfw.transform.field import Band, PhasorField, PhotonCounts, regular_grid_spacing
    from nlosfw.transform.field_io import read_phasor_field, write_phasor_field
    from nlosfw.transform.frequencies import (
        aliasing_warning,
        band_warning,
        default_band,
        dft_length,
        spatial_limit,
        temporal_nyquist,
        uniform_step,
        wall_spacing,
        warn_aliasing,
    )
    from nlosfw.transform.interface import PhasorTransform, PhasorTransformConfig
    from nlosfw.transform.temporal_dft import temporal_dft, unit_phasor
    from nlosfw.transform.wavelet import GaussianWavelet, WaveletTransform, WaveletTransformConfig

__all__ = [
    "aliasing_warning",
    "Band",
    "band_warning",
    "default_band",
    "dft_length",
    "FFTTransform",
    "FFTTransformConfig",
    "GaussianWavelet",
    "PhasorField",
    "PhotonCounts",
    "PhasorTransform",
    "PhasorTransformConfig",
    "read_phasor_field",
    "regular_grid_spacing",
    "spatial_limit",
    "temporal_dft",
    "temporal_nyquist",
    "uniform_step",
    "unit_phasor",
    "wall_spacing",
    "warn_aliasing",
    "WaveletTransform",
    "WaveletTransformConfig",
    "write_phasor_field",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__)

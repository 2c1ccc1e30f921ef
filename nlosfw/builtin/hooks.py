"""Registration of the built-in plugins.

This module is the core distribution's ``nlosfw`` entry point: the built-ins
register through exactly the same hooks as third-party plugins. Factories and
config classes are named by import path so nothing is imported until used.
"""

from __future__ import annotations

from typing import Any

from nlosfw.plugins.hookspecs import hookimpl


@hookimpl
def register_simulators(register: Any) -> None:
    register(
        "analytic",
        "nlosfw.builtin.analytic:AnalyticSimulator",
        config="nlosfw.builtin.analytic:AnalyticConfig",
        description="Exact three-bounce transients of points and patches (no visibility)",
        test_config={"patch_size": 0.05},
        expected_failures={"check_occlusion": "no visibility: the analytic simulator ignores "
                           "shadowing (by design; use a ray tracer such as embree)"},
    )


@hookimpl
def register_phasor_transforms(register: Any) -> None:
    register(
        "fft",
        "nlosfw.builtin.fft_transform:FFTTransform",
        config="nlosfw.builtin.fft_transform:FFTTransformConfig",
        description="Temporal Fourier transform at any set of frequencies",
        test_config={"n_frequencies": 16},
    )
    register(
        "wavelet",
        "nlosfw.builtin.wavelet_transform:WaveletTransform",
        config="nlosfw.builtin.wavelet_transform:WaveletTransformConfig",
        description="Liu's Gaussian-enveloped virtual illumination (spectral bins and weights)",
        test_config={"n_cycles": 4.0},
    )


@hookimpl
def register_field_models(register: Any) -> None:
    register(
        "interp",
        "nlosfw.builtin.interp:InterpFieldModel",
        config="nlosfw.builtin.interp:InterpConfig",
        description="Cubic interpolation of the complex field in x, y and frequency (baseline)",
    )


@hookimpl
def register_imagers(register: Any) -> None:
    register(
        "rsd",
        "nlosfw.builtin.rsd_imager:RSDImager",
        config="nlosfw.builtin.rsd_imager:RSDImagerConfig",
        description="Direct Rayleigh-Sommerfeld sum over any voxel set",
        test_config={"chunk_mb": 1.0},
    )
    register(
        "fft",
        "nlosfw.builtin.fft_imager:FFTImager",
        config="nlosfw.builtin.fft_imager:FFTImagerConfig",
        description="Fast RSD: per-plane FFT convolution (Liu 2020)",
        test_config={"workers": 2},
    )

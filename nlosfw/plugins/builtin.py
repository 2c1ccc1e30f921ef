"""Registration of the built-in plugins.

This module is the core distribution's ``nlosfw`` entry point: the built-ins
register through exactly the same hooks as third-party plugins. Factories and
config classes are named by import path so nothing is imported until used.
Capabilities (what the conformance kit checks) are listed in
:mod:`nlosfw.plugins.capabilities`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlosfw.plugins.capabilities import Capability as C
from nlosfw.plugins.hookspecs import hookimpl

if TYPE_CHECKING:
    from nlosfw.plugins.registry import Registrar


@hookimpl
def register_simulators(register: Registrar) -> None:
    register(
        "analytic",
        "nlosfw.simulate.analytic:AnalyticSimulator",
        config="nlosfw.simulate.analytic:AnalyticConfig",
        description="Exact three-bounce transients of points and patches (no visibility)",
        test_config={"patch_size": 0.05},
        # no occlusion (nothing shadows anything) and no mesh files: see its module docstring
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.DEVICE_LEGS],
    )


@hookimpl
def register_phasor_transforms(register: Registrar) -> None:
    register(
        "fft",
        "nlosfw.transform.fft:FFTTransform",
        config="nlosfw.transform.fft:FFTTransformConfig",
        description="Temporal Fourier transform at any set of frequencies",
        test_config={"n_frequencies": 16},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.ANY_FREQUENCIES],
    )
    register(
        "wavelet",
        "nlosfw.transform.wavelet:WaveletTransform",
        config="nlosfw.transform.wavelet:WaveletTransformConfig",
        description="Liu's Gaussian-enveloped virtual illumination (spectral bins and weights)",
        test_config={"n_cycles": 4.0},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.SPECTRAL_WEIGHTS, C.GAUSSIAN_WAVELET],
    )


@hookimpl
def register_field_models(register: Registrar) -> None:
    register(
        "interp",
        "nlosfw.model.interp:InterpFieldModel",
        config="nlosfw.model.interp:InterpConfig",
        description="Cubic interpolation of the complex field in x, y and frequency (baseline)",
        capabilities=[C.MULTI_FREQUENCY, C.SINGLE_FREQUENCY, C.SAVE_LOAD],
    )
    register(
        "rsd_prior",
        "nlosfw.model.physics.prior:RSDPriorFieldModel",
        config="nlosfw.model.physics.prior:RSDPriorConfig",
        description="Non-negative hidden albedo fitted by FISTA, propagated to the wall (RSD)",
        test_config={"iterations": 150, "amplitude": "point", "l1_weight": 0.001,
                     "workers": 1},
        # physical_prior: it fits only fields a hidden scene can produce, so the kit fits
        # it on a point scatterer's field (the kit's point fixture has no surface normal:
        # amplitude "point"). No single_frequency: one frequency cannot place the scene in
        # depth. Not neural: the fit is deterministic (the seed only starts the power
        # iteration).
        capabilities=[C.MULTI_FREQUENCY, C.SAVE_LOAD, C.PHYSICAL_PRIOR],
    )


@hookimpl
def register_imagers(register: Registrar) -> None:
    register(
        "rsd",
        "nlosfw.image.rsd:RSDImager",
        config="nlosfw.image.rsd:RSDImagerConfig",
        description="Direct Rayleigh-Sommerfeld sum over any voxel set",
        test_config={"chunk_mb": 1.0},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.PLANE_VOXELS, C.POINT_VOXELS, C.RSD,
                      C.PROGRESS],
    )
    register(
        "fft",
        "nlosfw.image.fft:FFTImager",
        config="nlosfw.image.fft:FFTImagerConfig",
        description="Fast RSD: per-plane FFT convolution (Liu 2020)",
        test_config={"workers": 2},
        capabilities=[C.SINGLE_SPOT, C.CONFOCAL, C.PLANE_VOXELS, C.RSD, C.PROGRESS, C.GPU],
    )
    # the classical confocal imagers, on the field's transient (nlosfw.image.transient)
    register(
        "lct",
        "nlosfw.image.lct:LCTImager",
        config="nlosfw.image.lct:LCTImagerConfig",
        description="Light-cone transform with a Wiener filter (O'Toole 2018), confocal",
        capabilities=[C.CONFOCAL, C.PLANE_VOXELS, C.PROGRESS, C.GPU],
    )
    register(
        "fk",
        "nlosfw.image.fk:FKImager",
        config="nlosfw.image.transient:TransientImagerConfig",
        description="f-k (Stolt) migration (Lindell 2019), confocal",
        capabilities=[C.CONFOCAL, C.PLANE_VOXELS, C.PROGRESS, C.GPU],
    )
    register(
        "fbp",
        "nlosfw.image.lct:FBPImager",
        config="nlosfw.image.lct:FBPImagerConfig",
        description="Backprojection with a Laplacian filter along depth, confocal",
        capabilities=[C.CONFOCAL, C.PLANE_VOXELS, C.PROGRESS, C.GPU],
    )


@hookimpl
def register_capture_formats(register: Registrar) -> None:
    register(
        "nlosfw",
        "nlosfw.capture.ytal:NlosfwFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="nlosfw's capture files: y-tal's HDF5 layout with nlosfw_type attributes",
        capabilities=[C.READABLE, C.WRITABLE],
    )
    register(
        "ytal",
        "nlosfw.capture.ytal:YtalFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="y-tal HDF5 captures (tal.io.write_capture)",
        capabilities=[C.READABLE, C.WRITABLE],
    )
    register(
        "znlos",
        "nlosfw.capture.znlos:ZnlosFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="Zaragoza NLOS dataset HDF5 (Galindo et al. 2019)",
        capabilities=[C.READABLE],
    )
    register(
        "lct",
        "nlosfw.capture.lct:LctFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="Stanford LCT .mat (O'Toole 2018): rect_data, width; gates 600 bins",
        capabilities=[C.READABLE],
    )
    register(
        "fk",
        "nlosfw.capture.fk:FkFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="Stanford f-k .mat v7.3 (Lindell 2019): meas, tof.mat delays, 512 bins",
        capabilities=[C.READABLE],
    )
    register(
        "wisconsin",
        "nlosfw.capture.wisconsin:WisconsinFormat",
        config="nlosfw.capture.formats:CaptureFormatConfig",
        description="Wisconsin/Zaragoza phasor-field .mat v7.3 (Liu 2019, 2020), as y-tal reads it",
        capabilities=[C.READABLE],
    )

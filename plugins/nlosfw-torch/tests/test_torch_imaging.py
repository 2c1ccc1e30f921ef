"""The FFT-based imagers (fft, lct, fk, fbp) on the torch array backend: ``imager.device``.

The device code runs on torch's CPU device here and must give the numpy imagers' image
within 1e-4 relative on a closed-form point scatterer's field; on CUDA the same, where a
CUDA device exists. ``auto`` without one is the numpy code, torch not imported for it.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nlosfw_torch.arrays import TorchArrays  # noqa: E402

from nlosfw.plugins import ArrayBackendSpec, bind_device, load_plugins  # noqa: E402
from nlosfw.testing import fixtures  # noqa: E402

FREQUENCIES = np.linspace(2.0, 30.0, 57)
TARGET = (0.05, -0.03, 0.45)
DEPTHS = np.linspace(0.3, 0.6, 13)
#: (imager, its options, confocal): each imager's paths (the fft imager's fast single
#: precision, exact double, incoherent sum and single-spot laser leg; the transient
#: imagers' filters).
CASES = [
    ("fft", {}, True),
    ("fft", {"precision": "double"}, True),
    ("fft", {"combine": "incoherent"}, True),
    ("fft", {}, False),
    ("fft", {"time": 0.05}, False),
    ("lct", {}, True),
    ("lct", {"falloff": "retroreflective", "snr": 0.8}, True),
    ("fk", {}, True),
    ("fbp", {}, True),
    ("fbp", {"wiener": False}, True),
]
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device"))]


def _field_and_voxels(confocal: bool):
    field = fixtures.point_field(TARGET, (24, 24), 0.6 / 24, FREQUENCIES, confocal=confocal)
    return field, fixtures.aligned_voxels(field.wall_xyz, DEPTHS)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(("name", "options", "confocal"), CASES,
                         ids=[f"{n}-{'-'.join(f'{k}={v}' for k, v in o.items()) or 'default'}"
                              f"-{'confocal' if c else 'single_spot'}" for n, o, c in CASES])
def test_the_device_code_gives_the_numpy_image(name, options, confocal, device):
    field, voxels = _field_and_voxels(confocal)
    imager = load_plugins().registry.create("imager", name, options)
    assert imager.arrays is None                                 # the default: numpy
    numpy_image = imager.reconstruct(field, voxels)
    device_image = imager.on(TorchArrays(device)).reconstruct(field, voxels)
    a, b = numpy_image.intensity, device_image.intensity
    assert b.shape == a.shape and b.dtype == np.float64
    assert np.linalg.norm(b - a) / np.linalg.norm(a) <= 1e-4
    assert np.abs(b - a).max() <= 1e-4 * np.abs(a).max()
    peak = np.unravel_index(np.argmax(a), a.shape)
    assert abs(DEPTHS[peak[0]] - TARGET[2]) <= 0.03               # a real image of the point
    assert device_image.metadata["device"] == str(torch.device(device))
    assert "device" not in numpy_image.metadata


@pytest.mark.parametrize("name", ["fft", "lct", "fk", "fbp"])
def test_auto_without_a_gpu_is_the_numpy_code(name):
    registry = load_plugins().registry
    assert registry.array_backends["torch"].devices == ("cuda",)
    for device in ("auto", "cpu"):
        imager = registry.create("imager", name, {"device": device})
        assert bind_device(imager, registry.array_backends, gpu_driver=False).arrays is None
        if not torch.cuda.is_available():
            assert imager.arrays is None


class _SeesOne(ArrayBackendSpec):
    """A backend that counts one CUDA device and computes on torch's CPU (this machine need
    not have a GPU)."""

    def count(self, kind: str) -> int:
        return 1

    def create(self, device: str) -> TorchArrays:  # type: ignore[override]
        return TorchArrays("cpu")


@pytest.mark.parametrize("name", ["fft", "lct", "fk", "fbp"])
def test_auto_and_cuda_bind_the_backend_that_sees_a_device(name):
    backends = {"torch": _SeesOne("torch", "-", "-", ("cuda",))}
    registry = load_plugins().registry
    for device in ("auto", "cuda"):
        imager = registry.create("imager", name, {"device": "cpu"})
        imager = type(imager)(type(imager.config)(device=device))
        assert isinstance(bind_device(imager, backends, gpu_driver=True).arrays, TorchArrays)
    auto = type(imager)(type(imager.config)(device="auto"))
    assert bind_device(auto, backends, gpu_driver=False).arrays is None
    cpu = type(imager)(type(imager.config)(device="cpu"))
    assert bind_device(cpu, backends, gpu_driver=True).arrays is None


def test_listing_plugins_and_auto_do_not_import_torch():
    code = ("import sys\n"
            "from nlosfw.plugins import load_plugins\n"
            "r = load_plugins().registry\n"
            "assert 'torch' in r.array_backends\n"
            "from nlosfw.plugins.array_backends import nvidia_driver_present\n"
            "if not nvidia_driver_present():\n"
            "    assert r.create('imager', 'fft', {'device': 'auto'}).arrays is None\n"
            "print('torch' in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "False", done.stderr

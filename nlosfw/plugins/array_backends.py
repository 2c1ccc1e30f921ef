"""Array backends of the FFT-based imagers, registered by plugins, and ``imager.device``.

A plugin module registers one in its ``register_array_backends(register)`` hook::

    register("torch", factory="nlosfw_torch.arrays:TorchArrays",
             counter="nlosfw_torch.arrays:device_count", devices=["cuda"])

(both named ``"module:attribute"``): ``factory(device)`` builds the
:class:`~nlosfw.image.arrays.ArrayOps` of one device; ``counter(kind)`` says how many
devices of ``kind`` the machine has. Nothing is imported at registration. An imager with a
``device`` option (:class:`~nlosfw.image.arrays.DeviceImager`) that the registry builds is
bound to the backend its option selects (:func:`bind_device`); :func:`check_device`
refuses ``cuda`` before a run when no backend sees one. ``auto`` asks a backend only on a
machine that has an NVIDIA driver, so that a machine without a GPU never imports torch
for it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import cast

from nlosfw.common.errors import ConfigError, PluginError
from nlosfw.image.arrays import ArrayOps, Device, DeviceImager

#: The option every error names.
OPTION = "imager.device"
#: What is valid, said in every error.
VALID = ", ".join(d.value for d in Device)


@dataclass(frozen=True)
class ArrayBackendSpec:
    """One registered array backend: its name, factory, device counter, the device kinds
    it runs on and the distribution that registered it."""

    name: str
    factory: str
    counter: str
    devices: tuple[str, ...]
    distribution: str = ""

    def count(self, kind: str) -> int:
        """How many devices of ``kind`` the backend sees (imports it)."""
        count = _load(self.counter)(kind)
        if not isinstance(count, int):
            raise PluginError(f"array backend '{self.name}': {self.counter} returned "
                              f"{type(count).__name__}, not a number of devices")
        return count

    def create(self, device: str) -> ArrayOps:
        """The backend's array operations on ``device``."""
        arrays = _load(self.factory)(device)
        return cast(ArrayOps, arrays)


def _load(path: str) -> Callable[[str], object]:
    """The object ``"module:attribute"`` names (imports the module)."""
    module, _, attribute = path.partition(":")
    loaded: Callable[[str], object] = getattr(importlib.import_module(module), attribute)
    return loaded


class ArrayBackendRegistrar:
    """The ``register`` callable of ``register_array_backends``: adds to ``into``."""

    def __init__(self, distribution: str, into: dict[str, ArrayBackendSpec]) -> None:
        self.distribution = distribution
        self.into = into

    def __call__(self, name: str, factory: str, counter: str,
                 devices: Iterable[str] = ("cuda",)) -> None:
        if name in self.into:
            raise PluginError(f"duplicate array backend '{name}': registered by "
                              f"{self.into[name].distribution} and by {self.distribution}")
        self.into[name] = ArrayBackendSpec(name, factory, counter, tuple(devices),
                                           self.distribution)


def nvidia_driver_present(root: Path = Path("/")) -> bool:
    """Whether this machine has an NVIDIA driver loaded (a CUDA device may exist), read
    from the file system without importing any GPU library."""
    return (root / "proc" / "driver" / "nvidia").is_dir() or any(
        (root / "dev").glob("nvidia[0-9]*"))


def _cuda_backend(backends: Mapping[str, ArrayBackendSpec]) -> ArrayBackendSpec | None:
    """The first backend (by name) that runs on CUDA and sees a device; None otherwise."""
    for name in sorted(backends):
        spec = backends[name]
        if "cuda" in spec.devices and spec.count("cuda") > 0:
            return spec
    return None


def check_device(device: str, backends: Mapping[str, ArrayBackendSpec]) -> None:
    """Before a run: a one-line ConfigError on ``imager.device`` for ``cuda`` when no
    registered backend sees a CUDA device (``cpu`` and ``auto`` always run)."""
    if Device(device) is not Device.cuda:
        return
    offering = [s.name for s in backends.values() if "cuda" in s.devices]
    if not offering:
        raise ConfigError(OPTION, "cuda needs an array backend plugin for CUDA (install "
                          "plugins/nlosfw-torch), and none is installed; valid here: auto, cpu")
    if _cuda_backend(backends) is None:
        raise ConfigError(OPTION, f"cuda: {', '.join(sorted(offering))} sees no CUDA device "
                          "on this machine; valid here: auto, cpu (all: " + VALID + ")")


def bind_device(imager: object, backends: Mapping[str, ArrayBackendSpec],
                gpu_driver: bool | None = None) -> object:
    """``imager`` bound to the array backend its ``device`` option selects (itself for
    ``cpu``, for ``auto`` without a CUDA device, and for imagers without the option);
    a ConfigError for ``cuda`` without one (:func:`check_device`). ``gpu_driver``: whether
    the machine has an NVIDIA driver (None: :func:`nvidia_driver_present`), without which
    ``auto`` asks no backend."""
    device = getattr(getattr(imager, "config", None), "device", None)
    if not isinstance(imager, DeviceImager) or device is None:
        return imager
    device = Device(device)
    if device is Device.cpu:
        return imager
    if device is Device.auto:
        if not (nvidia_driver_present() if gpu_driver is None else gpu_driver):
            return imager
    else:
        check_device(device, backends)
    spec = _cuda_backend(backends)
    return imager if spec is None else imager.on(spec.create("cuda"))

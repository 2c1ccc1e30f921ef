"""What a plugin can do: the capability vocabulary of each plugin kind.

A plugin declares its capabilities on its class (``capabilities = ("confocal",
"occlusion")``, a class attribute of :class:`~nlosfw.common.config.Configurable`) or when
it registers (``register(..., capabilities=[...])``, which takes their place), as strings
or :class:`Capability` members. The conformance kit (:mod:`nlosfw.testing`)
chooses its checks from these declarations: a check that needs a capability the
plugin does not declare is skipped and says why, and a declared capability is
verified by the checks that need it.

Each kind has its own vocabulary (:data:`VOCABULARY`); a name outside it is an
error at registration. A plugin that declares nothing gets :data:`DEFAULTS`, the
contract every plugin of its kind was checked against before capabilities
existed, so existing third-party plugins keep exactly their checks.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from enum import Enum
from types import MappingProxyType

from nlosfw.common.errors import PluginError


class Capability(str, Enum):
    """One capability name; what it promises depends on the kind (see :data:`VOCABULARY`)."""

    # captures and geometry
    CONFOCAL = "confocal"
    SINGLE_SPOT = "single_spot"
    DEVICE_LEGS = "device_legs"
    # simulators
    OCCLUSION = "occlusion"
    MESH_FILES = "mesh_files"
    # transforms
    ANY_FREQUENCIES = "any_frequencies"
    SPECTRAL_WEIGHTS = "spectral_weights"
    GAUSSIAN_WAVELET = "gaussian_wavelet"
    # field models
    MULTI_FREQUENCY = "multi_frequency"
    SINGLE_FREQUENCY = "single_frequency"
    SAVE_LOAD = "save_load"
    NEURAL = "neural"
    PHYSICAL_PRIOR = "physical_prior"
    # imagers
    PLANE_VOXELS = "plane_voxels"
    POINT_VOXELS = "point_voxels"
    PROGRESS = "progress"
    RSD = "rsd"
    # capture formats
    READABLE = "readable"
    WRITABLE = "writable"
    # hardware
    GPU = "gpu"

    def __str__(self) -> str:
        return self.value


C = Capability

#: Per kind (by :class:`~nlosfw.plugins.PluginKind` value), each valid capability and what
#: it promises.
VOCABULARY: Mapping[str, Mapping[Capability, str]] = MappingProxyType({
    "simulator": MappingProxyType({
        C.SINGLE_SPOT: "renders single-spot captures (one laser spot, a grid of sensors)",
        C.CONFOCAL: "renders confocal captures (laser and sensor scan the same wall point)",
        C.DEVICE_LEGS: "counts the device-to-wall legs in the time axis when the scene asks",
        C.OCCLUSION: "hidden surfaces shadow each other (a visibility test on every path)",
        C.MESH_FILES: "renders mesh-file items (OBJ, PLY, STL, ...) like the same surfaces",
        C.GPU: "can run on a GPU (descriptive: no check needs it)",
    }),
    "transform": MappingProxyType({
        C.SINGLE_SPOT: "transforms single-spot captures",
        C.CONFOCAL: "transforms confocal captures",
        C.ANY_FREQUENCIES: "option `frequencies` (cycles/m): the field holds exactly those, "
                           "on or off the DFT bins",
        C.SPECTRAL_WEIGHTS: "the field carries virtual-illumination weights: the spectrum of a "
                            "pulse centred at t = 0",
        C.GAUSSIAN_WAVELET: "the weights are Liu's Gaussian wavelet with the options of "
                            "WaveletTransformConfig (the config derives from it)",
    }),
    "model": MappingProxyType({
        C.MULTI_FREQUENCY: "fits many frequencies as one function of (x, y, f) and predicts "
                           "between and beyond them",
        C.SINGLE_FREQUENCY: "fits a field of a single frequency and predicts it anywhere on "
                            "the wall",
        C.SAVE_LOAD: "save() writes one file that load() restores exactly",
        C.NEURAL: "trained from a random initialisation: the seed changes the fitted model",
        C.PHYSICAL_PRIOR: "represents only fields a hidden scene can produce through the "
                          "field's capture geometry (not any smooth function): the kit fits "
                          "it on a point scatterer's exact field instead of a sum of plane "
                          "waves",
        C.GPU: "can train on a GPU with device=auto (descriptive: no check needs it)",
    }),
    "imager": MappingProxyType({
        C.SINGLE_SPOT: "images single-spot fields",
        C.CONFOCAL: "images confocal fields",
        C.PLANE_VOXELS: "voxels in planes parallel to the wall on the wall's grid, "
                        "(Y, X, 3) or (Z, Y, X, 3)",
        C.POINT_VOXELS: "any voxel list (N, 3)",
        C.PROGRESS: "reconstruct(..., on_progress=callback) reports (done, total) as blocks of "
                    "voxels finish, the last time with done == total",
        C.RSD: "its image is the field's Rayleigh-Sommerfeld image (the reference RSD's); "
               "classical imagers (lct, fk, fbp) image the field's transient otherwise",
        C.GPU: "option `device` (auto, cpu, cuda): images on a GPU through an array backend "
               "plugin, nlosfw-torch's (descriptive: no check needs it)",
    }),
    "capture_format": MappingProxyType({
        C.READABLE: "recognises its files by their content and reads them as captures",
        C.WRITABLE: "writes captures in its layout (and reads them back unchanged)",
    }),
})

#: What a plugin that declares nothing is taken to declare: per kind, what every plugin
#: of the kind was checked for before capabilities existed.
DEFAULTS: Mapping[str, frozenset[Capability]] = MappingProxyType({
    "simulator": frozenset({C.SINGLE_SPOT, C.CONFOCAL, C.DEVICE_LEGS, C.OCCLUSION}),
    "transform": frozenset({C.SINGLE_SPOT, C.CONFOCAL}),
    "model": frozenset({C.MULTI_FREQUENCY, C.SAVE_LOAD}),
    "imager": frozenset({C.SINGLE_SPOT, C.CONFOCAL, C.PLANE_VOXELS, C.RSD}),
    "capture_format": frozenset({C.READABLE}),
})


def vocabulary(kind: str | Enum) -> Mapping[Capability, str]:
    """The capabilities a plugin of ``kind`` may declare, each with what it promises."""
    key = kind.value if isinstance(kind, Enum) else str(kind)
    try:
        return VOCABULARY[key]
    except KeyError:
        raise PluginError(f"unknown plugin kind {key!r}; valid: "
                          f"{', '.join(VOCABULARY)}") from None


def parse_capabilities(kind: str | Enum, plugin: str,
                       declared: Iterable[str | Capability] | None) -> frozenset[Capability]:
    """The declared capabilities as a set; ``None`` gives the kind's :data:`DEFAULTS`.

    ``plugin`` names the plugin in the one-line :class:`PluginError` raised for a
    name outside the kind's vocabulary.
    """
    key = kind.value if isinstance(kind, Enum) else str(kind)
    valid = vocabulary(key)
    if declared is None:
        return DEFAULTS[key]
    names = ", ".join(sorted(c.value for c in valid))
    if isinstance(declared, (str, Capability)) or not isinstance(declared, Iterable):
        raise PluginError(f"{plugin}: capabilities must be a list of names, not "
                          f"{str(declared)!r}; valid: {names}")
    found = set()
    for item in declared:
        value = item.value if isinstance(item, Capability) else item
        capability = next((c for c in valid if c.value == value), None)
        if capability is None:
            raise PluginError(f"{plugin} declares unknown capability {value!r}; valid: {names}")
        found.add(capability)
    return frozenset(found)


def format_capabilities(capabilities: Iterable[Capability]) -> str:
    """Sorted, comma-separated names ('none' for an empty set)."""
    return ", ".join(sorted(c.value for c in capabilities)) or "none"

"""The kinds of plugin and the interface each must implement."""

from __future__ import annotations

from enum import Enum

from nlosfw.capture.formats import CaptureFormat
from nlosfw.common.config import Configurable
from nlosfw.image.interface import Imager
from nlosfw.model.interface import FieldModel
from nlosfw.simulate.interface import Simulator
from nlosfw.transform.interface import PhasorTransform


class PluginKind(str, Enum):
    """The pluggable interfaces."""

    SIMULATOR = "simulator"
    PHASOR_TRANSFORM = "transform"
    FIELD_MODEL = "model"
    IMAGER = "imager"
    CAPTURE_FORMAT = "capture_format"
    """Readers and writers of capture files; chosen by ``capture.format`` or detected from
    the file, not a config group of the run (``capture`` is the group of ``capture.path``)."""


#: The kinds a run selects one plugin of, each a Hydra config group (``model=interp``).
RUN_KINDS: tuple[PluginKind, ...] = (PluginKind.SIMULATOR, PluginKind.PHASOR_TRANSFORM,
                                     PluginKind.FIELD_MODEL, PluginKind.IMAGER)


#: The interface class of each plugin kind (by :class:`PluginKind` value).
INTERFACES: dict[str, type[Configurable]] = {
    "simulator": Simulator,
    "transform": PhasorTransform,
    "model": FieldModel,
    "imager": Imager,
    "capture_format": CaptureFormat,
}

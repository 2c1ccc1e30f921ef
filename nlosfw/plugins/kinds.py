"""The kinds of plugin and the interface each must implement."""

from __future__ import annotations

from enum import Enum

from nlosfw.common.config import Configurable
from nlosfw.image.interface import Imager
from nlosfw.model.interface import FieldModel
from nlosfw.simulate.interface import Simulator
from nlosfw.transform.interface import PhasorTransform


class PluginKind(str, Enum):
    """The four pluggable interfaces."""

    SIMULATOR = "simulator"
    PHASOR_TRANSFORM = "transform"
    FIELD_MODEL = "model"
    IMAGER = "imager"


#: The interface class of each plugin kind (by :class:`PluginKind` value).
INTERFACES: dict[str, type[Configurable]] = {
    "simulator": Simulator,
    "transform": PhasorTransform,
    "model": FieldModel,
    "imager": Imager,
}

"""The pre-run checks of a run's capture: what the run will do to it and with it.

A capture file is read and preprocessed by the checks themselves (see
:func:`nlosfw.compose.checks.validate_config`). A simulated capture is not simulated
before the run, but its scene states its layout (time axis, scan grid, laser points):
:func:`check_scene_preprocessing` puts a stand-in of that layout, every value zero,
through the run's preprocessing, so an option that does not fit it is refused before the
run as it would be for a file. Either way the plugins that take the capture must take
its kind (:func:`check_capture_kind`: an imager of confocal captures, a single-spot scene).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.preprocess import Preprocessing
from nlosfw.capture.source import FormatCatalogue, prepare, read_capture_file
from nlosfw.capture.time_axis import check_background
from nlosfw.common.errors import ConfigError
from nlosfw.common.inputs import regular_file
from nlosfw.plugins import PluginHost, PluginKind
from nlosfw.plugins.capabilities import Capability
from nlosfw.simulate.interface import scene_capture
from nlosfw.simulate.scene import Scene

#: The capability a plugin declares for each kind of capture it takes.
_KIND_CAPABILITY = {CaptureKind.SINGLE_SPOT: Capability.SINGLE_SPOT,
                    CaptureKind.CONFOCAL: Capability.CONFOCAL}


def scene_stand_in(scene: Scene) -> Capture:
    """A capture in the layout every simulator returns for ``scene`` (its time axis, scan
    grid and laser points: :func:`~nlosfw.simulate.interface.scene_capture`), every value
    zero."""
    bins, (nx, ny) = scene.time.bins, scene.wall.resolution
    return scene_capture(scene, np.zeros((bins, nx, ny), dtype=np.float32))


def check_scene_preprocessing(scene: Scene, options: Preprocessing,
                              formats: FormatCatalogue) -> Capture:
    """The stand-in of ``scene``'s capture after ``options`` (a ConfigError naming the
    option that does not fit its time axis or scan grid, or a file it names that cannot be
    read). The pile-up correction and the background subtraction need the values, not the
    layout: the background's layout is compared with the capture's instead."""
    stand_in = scene_stand_in(scene)
    if options.background:
        path = regular_file(options.background, "capture.background")
        check_background(stand_in, read_capture_file(path, None, formats)[2])
    layout = dataclasses.replace(options, pileup_pulses=None, background=None)
    return prepare(stand_in, layout, frozenset(), formats).capture


def check_capture_kind(capture: Capture, cfg: Mapping[str, object], host: PluginHost,
                       what: str, groups: Sequence[PluginKind] = (PluginKind.PHASOR_TRANSFORM,
                                                                  PluginKind.IMAGER)) -> None:
    """A ConfigError naming the plugin group when the plugin ``cfg`` selects there does not
    declare the kind of ``capture`` (single spot or confocal; ``what`` names the capture)
    among its capabilities. An exhaustive capture has no such capability: not checked."""
    needed = _KIND_CAPABILITY.get(capture.kind)
    if needed is None:
        return
    kind = capture.kind.value
    for group in groups:
        node = cfg.get(group.value)
        if not isinstance(node, Mapping) or node.get("name") is None:
            continue
        name = str(node.get("name"))
        capabilities = host.registry.get(group, name).capabilities
        if needed in capabilities:
            continue
        takes = " and ".join(sorted(c.value for c in capabilities if c in _KIND_CAPABILITY.values())
                             ) or "neither single_spot nor confocal"
        raise ConfigError(group.value, f"{name} takes {takes} captures, and {what} is {kind}; "
                                       f"choose a {group.value} that takes {kind} captures")

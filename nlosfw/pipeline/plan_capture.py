"""The capture of a run's plan: what it is, its size, and the checks of what the run will do
to it and with it (part of :func:`nlosfw.pipeline.make_plan`).

A capture file is read and preprocessed here, once (:func:`~nlosfw.capture.open_capture`):
the capture stage uses that read. A simulated capture is not simulated before the run,
but its scene states its layout (time axis, scan grid, laser points):
:func:`check_scene_preprocessing` puts a stand-in of that layout, every value zero,
through the run's preprocessing, so an option that does not fit it is refused before the
run as it would be for a file. Either way the plugins that take the capture must take
its kind (:func:`check_capture_kind`: an imager of confocal captures, a single-spot
scene), and what the run needs of it (photon counts) is checked.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.capture.photon_counts import photon_counts
from nlosfw.capture.preprocess import Preprocessing
from nlosfw.capture.source import FileCapture, FormatCatalogue, prepare, read_capture_file
from nlosfw.capture.time_axis import check_background
from nlosfw.common.errors import ConfigError
from nlosfw.common.inputs import regular_file
from nlosfw.common.memory import PlanShape
from nlosfw.evaluation.count_splitting import OPTION as SPLIT_OPTION
from nlosfw.evaluation.count_splitting import check_count_split
from nlosfw.evaluation.noise_floor import DFT_TRANSFORMS, kernel_power
from nlosfw.evaluation.splits import SpatialPattern, heldout_frequency_count
from nlosfw.model.interface import ModelNeeds
from nlosfw.pipeline.settings import SplitSettings
from nlosfw.plugins.capabilities import Capability
from nlosfw.simulate.interface import scene_capture
from nlosfw.simulate.scene import NoiseModel, Scene
from nlosfw.transform.counts import check_counts_times
from nlosfw.transform.frequencies import grid_spacing
from nlosfw.transform.interface import PhasorTransform

#: The capability a plugin declares for each kind of capture it takes.
_KIND_CAPABILITY = {CaptureKind.SINGLE_SPOT: Capability.SINGLE_SPOT,
                    CaptureKind.CONFOCAL: Capability.CONFOCAL}

#: The plugins that take a capture, by group: their name and capabilities.
Takers = Mapping[str, tuple[str, frozenset[Capability]]]


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


def check_capture_kind(capture: Capture, takers: Takers, what: str) -> None:
    """A ConfigError naming the plugin group when a plugin of ``takers`` does not declare
    the kind of ``capture`` (single spot or confocal; ``what`` names the capture) among its
    capabilities. An exhaustive capture has no such capability: not checked."""
    needed = _KIND_CAPABILITY.get(capture.kind)
    if needed is None:
        return
    kind = capture.kind.value
    for group, (name, capabilities) in takers.items():
        if needed in capabilities:
            continue
        takes = " and ".join(sorted(c.value for c in capabilities if c in _KIND_CAPABILITY.values())
                             ) or "neither single_spot nor confocal"
        raise ConfigError(group, f"{name} takes {takes} captures, and {what} is {kind}; "
                                 f"choose a {group} that takes {kind} captures")


def check_scene_counts(scene: Scene, count_splitting: bool, pileup: bool,
                       needs: ModelNeeds) -> None:
    """What needs photon counts is refused for a simulated capture without photon noise."""
    if scene.noise.model == NoiseModel.poisson:
        return
    if count_splitting:
        raise ConfigError(SPLIT_OPTION, "count splitting needs photon counts, but the "
                          "simulated capture has no photon noise; set scene.noise.model=poisson")
    if pileup:
        raise ConfigError("capture.pileup_pulses", "the pile-up correction needs photon "
                          "counts, but the simulated capture has no photon noise; set "
                          "scene.noise.model=poisson or leave it null")
    if needs.counts:
        raise ConfigError("model.likelihood", "a Poisson likelihood needs photon counts, but "
                          "the simulated capture has none; set scene.noise.model=poisson or "
                          "use least_squares")


def check_file_counts(loaded: FileCapture, count_splitting: bool, seed: int, needs: ModelNeeds,
                      transform: tuple[str, PhasorTransform]) -> None:
    """Count splitting and a Poisson likelihood need photon counts in the file's capture
    (after its preprocessing), a likelihood of the counts themselves the transform's
    times, and either a DFT-like transform (:func:`check_noise_floor`)."""
    capture, where = loaded.prepared.capture, str(loaded.path)
    if count_splitting:
        check_count_split(capture, seed, where)
        check_noise_floor(transform, capture)
    if needs.counts:
        likelihood = ("model.likelihood", "the Poisson likelihood")
        photon_counts(capture, where, *likelihood)
        if needs.photon_counts:
            check_counts_times(capture.geometry, transform[1].config, where)
        check_noise_floor(transform, capture, *likelihood)


def check_noise_floor(transform: tuple[str, PhasorTransform], capture: Capture,
                      option: str = SPLIT_OPTION, purpose: str = "count splitting"
                      ) -> None:
    """Count splitting's noise floor (and a Poisson likelihood) needs a DFT-like transform:
    the built-in ones are; another is probed on the capture (a ConfigError for ``option``
    when it is not)."""
    name, plugin = transform
    if name not in DFT_TRANSFORMS:
        kernel_power(plugin, capture, name, option, purpose)


def capture_shape(capture: Capture, transform: PhasorTransform, training: TrainingSplit,
                  depth_range: tuple[float, float] | None) -> PlanShape:
    """The sizes of a run of ``capture`` (a file's, read; a scene's stand-in) whose field
    ``transform`` makes and whose models train on ``training``."""
    bins = capture.n_bins
    grid = tuple(int(n) for n in capture.grid_shape)
    sensors = math.prod(grid)
    lasers = 1 if capture.kind is not CaptureKind.EXHAUSTIVE else max(
        1, int(np.prod(capture.laser_grid_xyz.shape[:-1])))
    frequencies = transform.planned_frequencies(capture)
    count = transform.frequency_count(bins) if frequencies is None else int(frequencies.size)
    wall = (grid[1], grid[0]) if len(grid) == 2 else None      # (ny, nx) of an X_Y_3 grid
    spacing = None
    if wall is not None:
        try:
            spacing = float(grid_spacing(capture.sensor_grid_xyz))
        except (ConfigError, ValueError):
            spacing = None
    end = capture.t_start + bins * capture.delta_t
    return training.sized(PlanShape(
        bins=bins, sensors=sensors, lasers=lasers, grid=wall, spacing=spacing,
        confocal=capture.kind is CaptureKind.CONFOCAL, frequencies=count,
        f_min=None if frequencies is None else float(frequencies.min()),
        f_max=None if frequencies is None else float(frequencies.max()),
        depth_range=depth_range, deepest=end / 2 if end > 0 else None))


def header_shape(shape: tuple[int, int, int], transform: PhasorTransform,
                 training: TrainingSplit) -> PlanShape:
    """The sizes of a run of a capture file known from its header alone: its transient's
    (time bins, sensor points, laser points); the geometry is known once it is read."""
    bins, sensors, lasers = shape
    count = transform.frequency_count(bins)
    return training.sized(PlanShape(bins=bins, sensors=sensors, lasers=lasers,
                                    frequencies=count))


@dataclasses.dataclass(frozen=True)
class TrainingSplit:
    """What the models train on, as far as sizes go: the grid of every ``step``-th wall
    point, the frequencies a ``spectral`` split of ``fraction`` keeps."""

    step: int
    spectral: str
    fraction: float

    @classmethod
    def of(cls, split: SplitSettings) -> TrainingSplit:
        """The sizes of ``split``: a random pattern's points are scattered over the whole
        wall grid, so its training grid is that grid, ``step`` 1 (``spatial_step`` only
        sets how many points it keeps, which no estimate counts)."""
        step = 1 if split.pattern == SpatialPattern.random else split.spatial_step
        return cls(step=step, spectral=str(split.spectral), fraction=split.spectral_fraction)

    def grid(self, wall: tuple[int, int]) -> tuple[int, int]:
        """The grid the training samples lie on: every ``step``-th point of ``wall``."""
        return (-(-wall[0] // self.step), -(-wall[1] // self.step))

    def frequencies(self, count: int) -> int:
        """The training frequencies of a field of ``count`` frequencies."""
        return max(1, count - heldout_frequency_count(count, self.spectral, self.fraction))

    def sized(self, shape: PlanShape) -> PlanShape:
        """``shape`` (a run's sizes) with what its models train on: the training
        frequencies, the training grid (on a known wall grid) and its ``step``."""
        return dataclasses.replace(
            shape, training_frequencies=self.frequencies(shape.frequencies),
            training=None if shape.grid is None else self.grid(shape.grid), step=self.step)

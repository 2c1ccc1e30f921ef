"""The preprocessing options of a capture (``capture.*`` of a run): :class:`Preprocessing` and
the gate, crop and bin width it holds."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from nlosfw.capture.data import MAX_DELTA_T, MIN_DELTA_T
from nlosfw.capture.geometry import SPEED_OF_LIGHT
from nlosfw.common.config import Choice, require
from nlosfw.common.errors import ConfigError

#: Metres of optical path per picosecond.
METRES_PER_PS = SPEED_OF_LIGHT * 1e-12


class FlipAxes(Choice):
    """Which scan axes ``capture.flip`` mirrors."""

    x = "x"
    y = "y"
    xy = "xy"


@dataclass(frozen=True)
class Gate:
    """Remove the direct reflection: zero every bin that starts before a time.

    Give ``bins`` or ``metres``, not both (neither: unset, the format's default applies).
    """

    bins: int | None = None
    """Zero bins 0 .. bins-1 of the time axis as read (0: no gate)."""
    metres: float | None = None
    """[m] Zero the bins that start before this optical path length (the capture's time
    axis)."""

    def __post_init__(self) -> None:
        require(self.bins is None or self.metres is None, "bins",
                "give the gate in bins or in metres, not both")
        require(self.bins is None or self.bins >= 0, "bins", f"must be >= 0, got {self.bins}")
        require(self.metres is None or not math.isnan(self.metres), "metres",
                "must be a number of metres, got nan")

    @property
    def is_set(self) -> bool:
        return self.bins is not None or self.metres is not None


@dataclass(frozen=True)
class TimeCrop:
    """Keep the bins [start, stop) of the time axis; ``t_start`` moves with ``start``.

    Give ``bins`` or ``metres``, not both.
    """

    bins: tuple[int, int] | None = None
    """[start, stop) in bins of the time axis as read."""
    metres: tuple[float, float] | None = None
    """[m] Start and stop (of optical path): the bins that overlap [start, stop) are kept."""

    def __post_init__(self) -> None:
        require(self.bins is None or self.metres is None, "bins",
                "give the crop in bins or in metres, not both")
        if self.bins is not None:
            start, stop = self.bins
            require(0 <= start < stop, "bins", f"must satisfy 0 <= start < stop, got "
                    f"{list(self.bins)}")
        if self.metres is not None:
            start_m, stop_m = self.metres
            require(not (math.isnan(start_m) or math.isnan(stop_m)), "metres",
                    f"must be numbers of metres, got {list(self.metres)}")
            require(start_m < stop_m, "metres", f"must satisfy start < stop, got "
                    f"{list(self.metres)}")

    @property
    def is_set(self) -> bool:
        return self.bins is not None or self.metres is not None


@dataclass(frozen=True)
class BinWidth:
    """Override the bin width read from the file. Give ``ps`` or ``metres``, not both."""

    ps: float | None = None
    """[ps] Time per bin (metres = ps * 1e-12 * c)."""
    metres: float | None = None
    """[m] Optical path per bin."""

    def __post_init__(self) -> None:
        require(self.ps is None or self.metres is None, "ps",
                "give the bin width in ps or in metres, not both")
        for name in ("ps", "metres"):
            value = getattr(self, name)
            require(value is None or value > 0, name, f"must be > 0, got {value}")
        width = self.in_metres
        if width is not None and not MIN_DELTA_T <= width <= MAX_DELTA_T:
            raise ConfigError("ps" if self.ps is not None else "metres",
                              f"gives a bin width of {width:g} m; valid: {MIN_DELTA_T:g} to "
                              f"{MAX_DELTA_T:g} m ({MIN_DELTA_T / METRES_PER_PS:g} to "
                              f"{MAX_DELTA_T / METRES_PER_PS:g} ps)")

    @property
    def is_set(self) -> bool:
        return self.ps is not None or self.metres is not None

    @property
    def in_metres(self) -> float | None:
        return self.metres if self.ps is None else self.ps * METRES_PER_PS


#: The value of one preprocessing option (a field of :class:`Preprocessing`).
OptionValue = Gate | TimeCrop | BinWidth | FlipAxes | bool | int | str | None


@dataclass(frozen=True)
class Preprocessing:
    """The preprocessing options (``capture.*`` of a run). ``None`` (or an unset gate, crop
    or bin width) means: the capture format's default, else nothing."""

    gate: Gate = dataclasses.field(default_factory=Gate)
    """Zero the first bins (the direct reflection off the wall): ``gate.bins`` or
    ``gate.metres`` of path from the time origin."""
    time_crop: TimeCrop = dataclasses.field(default_factory=TimeCrop)
    """Keep a window of the time axis: ``time_crop.bins`` or ``time_crop.metres``."""
    bin: int | None = None
    """Spatial binning: sum each k x k block of scan points into one (1: none)."""
    stride: int | None = None
    """Keep every k-th scan point in x and in y (1: all)."""
    flip: FlipAxes | None = None
    """Mirror the scan along x, y or both (its data, laser point and devices with it)."""
    transpose: bool | None = None
    """Swap the scan axes x and y (a mirror about the grid's diagonal)."""
    bin_width: BinWidth = dataclasses.field(default_factory=BinWidth)
    """Override the bin width the file states: ``bin_width.ps`` or ``bin_width.metres``."""
    tofgrid: str | None = None
    """A .mat file whose variable ``tofgrid`` holds per-pixel delays (picoseconds, as the
    f-k dataset ships them), removed by shifting each histogram left by
    floor(delay / bin width) bins; '' for none."""
    background: str | None = None
    """A capture of the same scan without the hidden scene, subtracted bin by bin."""
    pileup_pulses: int | None = None
    """Laser pulses per scan point: correct the detector's pile-up (Coates' estimator,
    :mod:`nlosfw.capture.pileup`) before every other step, the background capture's too;
    null: none. Needs raw photon counts."""

    def __post_init__(self) -> None:
        for name in ("bin", "stride", "pileup_pulses"):
            value = getattr(self, name)
            require(value is None or value >= 1, name, f"must be >= 1, got {value}")

    def merged_over(self, defaults: Preprocessing) -> tuple[Preprocessing, frozenset[str]]:
        """These options where set, else ``defaults``'; and the names taken from the
        defaults."""
        chosen: dict[str, Any] = {}
        from_defaults = set()
        for f in dataclasses.fields(Preprocessing):
            mine, theirs = getattr(self, f.name), getattr(defaults, f.name)
            if _is_set(mine) or not _is_set(theirs):
                chosen[f.name] = mine
            else:
                chosen[f.name] = theirs
                from_defaults.add(f.name)
        return Preprocessing(**chosen), frozenset(from_defaults)


def _is_set(value: OptionValue) -> bool:
    return value.is_set if isinstance(value, (Gate, TimeCrop, BinWidth)) else value is not None

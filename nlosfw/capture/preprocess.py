"""Preprocessing of a capture before its transform: pure functions, each returning a new one.

The run options ``capture.gate``, ``time_crop``, ``bin``, ``stride``, ``flip``,
``transpose``, ``bin_width``, ``tofgrid``, ``background`` and ``pileup_pulses``
(:class:`Preprocessing`) map one to one onto the functions of :mod:`nlosfw.capture.time_axis`,
:mod:`nlosfw.capture.scan_grid` (re-exported here) and :mod:`nlosfw.capture.pileup`.
:func:`preprocess` applies those that are set, in a fixed order (pileup_pulses, background,
bin_width, tofgrid, gate, time_crop, transpose, flip, bin, stride), and returns what it
did as :class:`AppliedStep` records (the values actually used and whether they came from
the run's options or the capture format's defaults), so a result can be reproduced.
Positions in bins refer to the time axis as read (after the per-pixel delays are
removed). No function modifies its input.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.pileup import correct_pileup
from nlosfw.capture.preprocess_options import (
    METRES_PER_PS,
    BinWidth,
    FlipAxes,
    Gate,
    OptionValue,
    Preprocessing,
    TimeCrop,
    _is_set,
)
from nlosfw.capture.scan_grid import (
    as_scan_grid,
    bin_scan,
    flip_scan,
    stride_scan,
    transpose_scan,
)
from nlosfw.capture.time_axis import (
    crop_bins,
    crop_time,
    gate_bins,
    remove_delays,
    subtract_background,
    zero_before,
)
from nlosfw.common.errors import ConfigError

__all__ = ["METRES_PER_PS", "AppliedStep", "BinWidth", "Extras", "FlipAxes", "Gate",
           "Preprocessing", "StepSource", "TimeCrop", "as_scan_grid", "bin_scan", "crop_bins",
           "crop_time", "flip_scan", "gate_bins", "preprocess", "remove_delays", "stride_scan",
           "subtract_background", "transpose_scan", "zero_before"]

StepSource = Literal["option", "format", "automatic"]
#: An option's value as the config spells it (of a gate, crop or bin width: its set fields).
StepValue = bool | int | float | str | None | dict[str, int | float | list[int] | list[float]]


@dataclass(frozen=True)
class AppliedStep:
    """One preprocessing step as applied: the option, its value as the config spells it,
    where the value came from (``option``, ``format``, or ``automatic`` for the one step
    taken without an option: a list of wall points that forms a regular grid becomes that
    grid) and what it did."""

    option: str
    value: StepValue
    source: StepSource
    effect: str

    def to_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Extras:
    """The data some steps need besides the capture: per-pixel delays (ps, on the capture's
    scan grid (X, Y)) and a background capture."""

    delays_ps: np.ndarray | None = None
    background: Capture | None = None
    source: str = "the capture"
    """What errors call the capture (its file, when read from one)."""


# ------------------------------------------------------------------------------ driver
def preprocess(capture: Capture, options: Preprocessing, from_format: frozenset[str] = frozenset(),
               extras: Extras = Extras()) -> tuple[Capture, tuple[AppliedStep, ...]]:
    """Apply every set option of ``options`` to ``capture`` in the documented order.

    ``from_format`` names the options that came from the format's defaults (recorded as
    such). ConfigError names ``capture.<option>`` and what is valid when a value does
    not fit this capture (a gate past the end of the histogram, a binning that does
    not divide the grid). The steps are also appended to ``scene_info["preprocessing"]``.
    """
    steps: list[AppliedStep] = []
    c = capture
    gridded = as_scan_grid(c)
    if gridded is not None:
        steps.append(AppliedStep("grid", "X_Y_3", "automatic",
                                 f"the {c.grid_shape[0]} listed wall points form the scan grid "
                                 f"{_dims(gridded.grid_shape)}"))
        c = gridded
    for option, step in _STEPS:
        value = getattr(options, option)
        if not _is_set(value) or value is False:
            continue
        try:
            result = step(c, options, extras)
        except ConfigError as err:
            if option not in from_format:
                raise
            raise ConfigError(err.option, f"{err.problem} (the capture format's default; set "
                                          f"capture.{option} to override it)") from None
        if result is None:
            continue
        c, effect = result
        source: StepSource = "format" if option in from_format else "option"
        steps.append(AppliedStep(option, _plain(value), source, effect))
    if steps:
        info = dict(c.scene_info)
        info["preprocessing"] = [*info.get("preprocessing", []), *(s.to_dict() for s in steps)]
        if any(s.option in ("transpose", "flip", "bin", "stride") for s in steps):
            info.pop("scan_layout", None)  # the file's scan order no longer applies
        c = c.replace(scene_info=info)
    return c, tuple(steps)


def _plain(value: OptionValue) -> StepValue:
    """An option's value as the config spells it (of a gate, crop or bin width: its set
    fields)."""
    if isinstance(value, (Gate, TimeCrop, BinWidth)):
        return {k: (list(v) if isinstance(v, tuple) else v)
                for k, v in dataclasses.asdict(value).items() if v is not None}
    return str(value) if isinstance(value, FlipAxes) else value


def _dims(shape: tuple[int, ...]) -> str:
    return "x".join(str(n) for n in shape)


StepResult = tuple[Capture, str] | None


def _pileup(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    assert o.pileup_pulses is not None
    out = correct_pileup(c, o.pileup_pulses, where=extras.source)
    worst = out.scene_info["pileup"]["largest_detection_probability"]
    return out, (f"Coates' correction over {o.pileup_pulses} pulses per scan point (at most "
                 f"{100 * worst:.3g}% of a point's pulses detected a photon)")


def _background(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    if extras.background is None:
        return None
    background = extras.background
    if o.pileup_pulses is not None:
        background = correct_pileup(background, o.pileup_pulses, where="capture.background")
        return (subtract_background(c, background),
                "corrected for pile-up like the capture, subtracted bin by bin")
    return subtract_background(c, background), "subtracted bin by bin"


def _bin_width(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    width = o.bin_width.in_metres
    assert width is not None  # the option is set
    return (c.replace(delta_t=width),
            f"bin width {c.delta_t:.6g} m -> {width:.6g} m ({width / METRES_PER_PS:.4g} ps)")


def _tofgrid(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    if extras.delays_ps is None:
        return None
    out, shifts = remove_delays(c, extras.delays_ps)
    return out, f"histograms shifted left by {int(shifts.min())} to {int(shifts.max())} bins"


def _gate(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    n = gate_bins(c, o.gate)
    effect = (f"zeroed bins 0 to {n - 1} (path < {c.t_start + n * c.delta_t:.4g} m)" if n
              else "nothing zeroed")
    return zero_before(c, n), effect


def _time_crop(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    start, stop = crop_bins(c, o.time_crop)
    out = crop_time(c, start, stop)
    return out, (f"kept bins {start} to {stop - 1} (path {out.t_start:.4g} to "
                 f"{out.t_start + out.n_bins * out.delta_t:.4g} m)")


def _transpose(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    return transpose_scan(c), "swapped the scan axes x and y"


def _flip(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    assert o.flip is not None
    return flip_scan(c, FlipAxes(o.flip)), f"mirrored the scan along {o.flip}"


def _bin(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    assert o.bin is not None
    if o.bin == 1:
        return None
    out = bin_scan(c, o.bin)
    return out, f"scan grid {_dims(c.grid_shape)} -> {_dims(out.grid_shape)}"


def _stride(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    assert o.stride is not None
    if o.stride == 1:
        return None
    out = stride_scan(c, o.stride)
    return out, f"scan grid {_dims(c.grid_shape)} -> {_dims(out.grid_shape)}"


#: The steps in the order :func:`preprocess` applies them, by option name.
_STEPS = (("pileup_pulses", _pileup), ("background", _background), ("bin_width", _bin_width),
          ("tofgrid", _tofgrid), ("gate", _gate), ("time_crop", _time_crop),
          ("transpose", _transpose), ("flip", _flip), ("bin", _bin), ("stride", _stride))


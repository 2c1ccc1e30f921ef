"""Preprocessing of a capture before its transform: pure functions, each returning a new one.

The run options ``capture.gate``, ``time_crop``, ``bin``, ``stride``, ``flip``,
``transpose``, ``bin_width``, ``tofgrid`` and ``background`` (:class:`Preprocessing`)
map one to one onto the functions here. :func:`preprocess` applies those that are set,
in a fixed order (background, bin_width, tofgrid, gate, time_crop, transpose, flip, bin,
stride), and returns what it did as :class:`AppliedStep` records (the values actually
used and whether they came from the run's options or the capture format's defaults), so
a result can be reproduced. Positions in bins refer to the time axis as read (after the
per-pixel delays are removed). No function modifies its input.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from nlosfw.capture.data import MAX_DELTA_T, MIN_DELTA_T, Capture
from nlosfw.capture.enums import CaptureKind, GridFormat, HFormat
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

    def __post_init__(self) -> None:
        for name in ("bin", "stride"):
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


def _is_set(value: Any) -> bool:
    return value.is_set if isinstance(value, (Gate, TimeCrop, BinWidth)) else value is not None


StepSource = Literal["option", "format", "automatic"]


@dataclass(frozen=True)
class AppliedStep:
    """One preprocessing step as applied: the option, its value as the config spells it,
    where the value came from (``option``, ``format``, or ``automatic`` for the one step
    taken without an option: a list of wall points that forms a regular grid becomes that
    grid) and what it did."""

    option: str
    value: Any
    source: StepSource
    effect: str

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Extras:
    """The data some steps need besides the capture: per-pixel delays (ps, on the capture's
    scan grid (X, Y)) and a background capture."""

    delays_ps: np.ndarray | None = None
    background: Capture | None = None


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


def _plain(value: Any) -> Any:
    """An option's value as the config spells it (of a gate, crop or bin width: its set
    fields)."""
    if isinstance(value, (Gate, TimeCrop, BinWidth)):
        return {k: (list(v) if isinstance(v, tuple) else v)
                for k, v in dataclasses.asdict(value).items() if v is not None}
    return str(value) if isinstance(value, FlipAxes) else value


def _dims(shape: tuple[int, ...]) -> str:
    return "x".join(str(n) for n in shape)


StepResult = tuple[Capture, str] | None


def _background(c: Capture, o: Preprocessing, extras: Extras) -> StepResult:
    if extras.background is None:
        return None
    return subtract_background(c, extras.background), "subtracted bin by bin"


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
_STEPS = (("background", _background), ("bin_width", _bin_width), ("tofgrid", _tofgrid),
          ("gate", _gate), ("time_crop", _time_crop), ("transpose", _transpose),
          ("flip", _flip), ("bin", _bin), ("stride", _stride))


# ----------------------------------------------------------------------------- time axis
def gate_bins(capture: Capture, gate: Gate, option: str = "capture.gate") -> int:
    """How many leading bins ``gate`` zeroes; ConfigError if it reaches the end."""
    if gate.bins is not None:
        n, name, value = int(gate.bins), "bins", f"{gate.bins} bins"
    else:
        assert gate.metres is not None
        n = max(0, int(np.ceil((gate.metres - capture.t_start) / capture.delta_t - 1e-9)))
        name, value = "metres", f"{gate.metres} m"
    if n >= capture.n_bins:
        end = capture.t_start + capture.n_bins * capture.delta_t
        raise ConfigError(f"{option}.{name}",
                          f"{value} is past the end of the histogram ({capture.n_bins} bins, "
                          f"path {capture.t_start:.4g} to {end:.4g} m); valid: fewer than "
                          f"{capture.n_bins} bins (0: no gate)")
    return n


def zero_before(capture: Capture, n: int) -> Capture:
    """A copy of ``capture`` with its first ``n`` bins zeroed."""
    H = np.array(capture.H, copy=True)
    H[:n] = 0
    return capture.replace(H=H)


def crop_bins(capture: Capture, crop: TimeCrop, option: str = "capture.time_crop"
              ) -> tuple[int, int]:
    """The bins [start, stop) ``crop`` keeps; ConfigError unless they lie in the histogram."""
    if crop.bins is not None:
        start, stop = (int(b) for b in crop.bins)
        name = "bins"
    else:
        assert crop.metres is not None
        lo, hi = crop.metres
        start = max(0, int(np.floor((lo - capture.t_start) / capture.delta_t + 1e-9)))
        stop = min(capture.n_bins, int(np.ceil((hi - capture.t_start) / capture.delta_t - 1e-9)))
        name = "metres"
    if not 0 <= start < stop <= capture.n_bins:
        end = capture.t_start + capture.n_bins * capture.delta_t
        raise ConfigError(f"{option}.{name}",
                          f"keeps bins [{start}, {stop}), outside the histogram ({capture.n_bins}"
                          f" bins, path {capture.t_start:.4g} to {end:.4g} m); valid: 0 <= "
                          f"start < stop <= {capture.n_bins}")
    return start, stop


def crop_time(capture: Capture, start: int, stop: int) -> Capture:
    """The bins [start, stop) of ``capture``; ``t_start`` moves to the new first bin."""
    return capture.replace(H=np.array(capture.H[start:stop], copy=True),
                           t_start=capture.t_start + start * capture.delta_t)


def remove_delays(capture: Capture, delays_ps: np.ndarray, option: str = "capture.tofgrid"
                  ) -> tuple[Capture, np.ndarray]:
    """Shift each scan point's histogram left by floor(delay / bin width) bins (zeros enter
    at the end; the authors' MATLAB code wraps them around instead); returns the capture
    and the shifts (X, Y) in bins."""
    _need_grid(capture, option)
    delays = np.asarray(delays_ps, dtype=float)
    if delays.shape != capture.grid_shape:
        raise ConfigError(option, f"per-pixel delays of shape {list(delays.shape)} do not match "
                                  f"the scan grid {list(capture.grid_shape)}")
    if not np.all(np.isfinite(delays)):
        raise ConfigError(option, "per-pixel delays contain NaN or inf")
    bin_ps = capture.delta_t / METRES_PER_PS
    shifts = np.floor(delays / bin_ps + 1e-9).astype(np.int64)
    n = capture.n_bins
    H = capture.H
    out = np.zeros(H.shape, dtype=H.dtype)
    for s in np.unique(shifts):
        mask = shifts == s
        if 0 <= s < n:
            out[: n - s, mask] = H[s:, mask]
        elif -n < s < 0:
            out[-s:, mask] = H[: n + s, mask]
    return capture.replace(H=out), shifts


def subtract_background(capture: Capture, background: Capture) -> Capture:
    """``capture`` minus ``background`` bin by bin (same shape, bins and scan points)."""
    if background.H.shape != capture.H.shape:
        raise ConfigError("capture.background", f"shape {list(background.H.shape)} does not "
                                                f"match the capture's {list(capture.H.shape)}")
    if not (np.isclose(background.delta_t, capture.delta_t, rtol=1e-6)
            and np.isclose(background.t_start, capture.t_start, rtol=0, atol=1e-9)):
        raise ConfigError("capture.background", f"time axis (bin {background.delta_t:.6g} m from "
                                                f"{background.t_start:.6g} m) differs from the "
                                                f"capture's (bin {capture.delta_t:.6g} m from "
                                                f"{capture.t_start:.6g} m)")
    if not np.allclose(background.sensor_grid_xyz, capture.sensor_grid_xyz, atol=1e-6):
        raise ConfigError("capture.background", "its scan points differ from the capture's")
    H = capture.H.astype(np.result_type(capture.H, background.H), copy=True)
    H -= background.H
    if not np.any(H):
        raise ConfigError("capture.background", "subtracting it leaves nothing: it equals the "
                                                "capture (give the background measurement)")
    return capture.replace(H=H)


# --------------------------------------------------------------------------- scan grid
def _two_points_left(capture: Capture, k: int, option: str) -> None:
    nx, ny = capture.grid_shape
    if k >= min(nx, ny):
        raise ConfigError(option, f"{k} leaves fewer than 2 x 2 points of the {nx}x{ny} scan "
                                  f"grid; valid: 1 to {max(min(nx, ny) - 1, 1)}")


def _need_grid(capture: Capture, option: str) -> None:
    if capture.H_format is not HFormat.T_Sx_Sy or capture.sensor_grid_format is not \
            GridFormat.X_Y_3:
        raise ConfigError(option, f"needs a capture on a scan grid (T_Sx_Sy, X_Y_3), got "
                                  f"{capture.H_format.name} with {capture.sensor_grid_format.name}")


def _regular_centre(capture: Capture, option: str) -> np.ndarray:
    """The centre (3,) of an axis-aligned regular scan grid in the plane z = 0."""
    _need_grid(capture, option)
    grid = capture.sensor_grid_xyz
    xs, ys = grid[:, 0, 0], grid[0, :, 1]
    expected = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
    if not (np.allclose(grid[..., :2], expected, atol=1e-6) and np.allclose(grid[..., 2], 0,
                                                                          atol=1e-6)):
        raise ConfigError(option, "needs an axis-aligned scan grid in the wall plane z = 0")
    return np.array([(xs.min() + xs.max()) / 2, (ys.min() + ys.max()) / 2, 0.0])


def _map_points(capture: Capture, fn: Any, fn_dir: Any) -> dict[str, Any]:
    """The laser point, devices and normals of ``capture`` with a point map ``fn`` and a
    direction map ``fn_dir`` applied (the sensor grid is handled by the caller)."""
    changes: dict[str, Any] = {}
    for name in ("sensor_xyz", "laser_xyz"):
        value = getattr(capture, name)
        if value is not None:
            changes[name] = fn(value)
    if capture.kind is CaptureKind.SINGLE_SPOT:
        changes["laser_grid_xyz"] = fn(capture.laser_grid_xyz)
        if capture.laser_grid_normals is not None:
            changes["laser_grid_normals"] = fn_dir(capture.laser_grid_normals)
    return changes


def _with_grid(capture: Capture, H: np.ndarray, grid: np.ndarray, normals: np.ndarray | None,
               changes: dict[str, Any]) -> Capture:
    if capture.kind is CaptureKind.CONFOCAL:
        changes["laser_grid_xyz"] = grid
        changes["laser_grid_normals"] = normals
    return capture.replace(H=np.ascontiguousarray(H), sensor_grid_xyz=grid,
                           sensor_grid_normals=normals, **changes)


def flip_scan(capture: Capture, axes: FlipAxes, option: str = "capture.flip") -> Capture:
    """Mirror the scan about its centre line(s): the data of each point moves to its mirror
    point, and the laser point and devices are mirrored with it (a physical mirror image)."""
    centre = _regular_centre(capture, option)
    dims = [d for d, name in ((0, "x"), (1, "y")) if name in axes.value]
    sign = np.ones(3)
    sign[dims] = -1

    def point(p: np.ndarray) -> np.ndarray:
        return centre + (np.asarray(p) - centre) * sign

    def direction(v: np.ndarray) -> np.ndarray:
        return np.asarray(v) * sign

    H = capture.H
    grid = capture.sensor_grid_xyz
    normals = capture.sensor_grid_normals
    for d in dims:  # mirror the points, then reverse the axis: the grid stays ascending
        H = np.flip(H, axis=1 + d)
        grid = np.flip(grid, axis=d)
        normals = None if normals is None else np.flip(normals, axis=d)
    return _with_grid(capture, H.copy(), point(grid), None if normals is None
                      else direction(normals), _map_points(capture, point, direction))


def transpose_scan(capture: Capture, option: str = "capture.transpose") -> Capture:
    """Swap the scan axes: a mirror about the grid's diagonal through its centre
    ((x, y) -> (y, x) relative to the centre), data, laser point and devices with it."""
    centre = _regular_centre(capture, option)

    def point(p: np.ndarray) -> np.ndarray:
        q = np.asarray(p) - centre
        return centre + q[..., [1, 0, 2]]

    def direction(v: np.ndarray) -> np.ndarray:
        return np.asarray(v)[..., [1, 0, 2]]

    H = np.swapaxes(capture.H, 1, 2).copy()
    grid = point(np.swapaxes(capture.sensor_grid_xyz, 0, 1))
    normals = capture.sensor_grid_normals
    normals = None if normals is None else direction(np.swapaxes(normals, 0, 1))
    return _with_grid(capture, H, grid, normals, _map_points(capture, point, direction))


def bin_scan(capture: Capture, k: int, option: str = "capture.bin") -> Capture:
    """Sum each k x k block of scan points into one, at the block's mean position."""
    _need_grid(capture, option)
    _two_points_left(capture, k, option)
    nx, ny = capture.grid_shape
    if nx % k or ny % k:
        raise ConfigError(option, f"{k} does not divide the scan grid {nx}x{ny}; valid: a "
                                  "common divisor of both sides")
    T = capture.n_bins
    H = capture.H.reshape(T, nx // k, k, ny // k, k).sum(axis=(2, 4))
    grid = capture.sensor_grid_xyz.reshape(nx // k, k, ny // k, k, 3).mean(axis=(1, 3))
    normals = capture.sensor_grid_normals
    if normals is not None:
        normals = normals.reshape(nx // k, k, ny // k, k, 3).mean(axis=(1, 3))
        normals = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return _with_grid(capture, H, grid, normals, {})


def stride_scan(capture: Capture, k: int, option: str = "capture.stride") -> Capture:
    """Every k-th scan point in x and in y (from the first)."""
    _need_grid(capture, option)
    _two_points_left(capture, k, option)
    H = capture.H[:, ::k, ::k].copy()
    grid = capture.sensor_grid_xyz[::k, ::k].copy()
    normals = capture.sensor_grid_normals
    normals = None if normals is None else normals[::k, ::k].copy()
    return _with_grid(capture, H, grid, normals, {})


def as_scan_grid(capture: Capture, rtol: float = 0.05) -> Capture | None:
    """A capture whose sensors are a list (T_Si, N_3) forming a complete, regular,
    axis-aligned grid in the wall plane z = 0, as that grid (T_Sx_Sy, X_Y_3, x and y
    ascending); None for any other capture. ``rtol``: tolerance on the positions, as a
    fraction of the grid spacing."""
    if capture.H_format is not HFormat.T_Si or capture.kind is CaptureKind.EXHAUSTIVE:
        return None
    pts = capture.sensor_points
    if pts.shape[0] < 4:
        return None
    axes = []
    for d in (0, 1):
        values = np.sort(pts[:, d])
        gaps = np.diff(values)
        step = float(gaps.max()) if gaps.size else 0.0
        if step <= 0:
            return None
        starts = np.concatenate([[0], np.flatnonzero(gaps > rtol * step) + 1])
        centres = np.array([values[a:b].mean() for a, b in
                            zip(starts, [*starts[1:], values.size], strict=True)])
        if centres.size > 1:
            spacing = np.diff(centres)
            if not np.allclose(spacing, spacing.mean(), rtol=rtol, atol=0):
                return None
        axes.append(centres)
    xs, ys = axes
    if xs.size * ys.size != pts.shape[0] or xs.size < 2 or ys.size < 2:
        return None
    dx, dy = float(xs[1] - xs[0]), float(ys[1] - ys[0])
    if np.abs(pts[:, 2]).max() > rtol * min(dx, dy):
        return None
    ix = np.rint((pts[:, 0] - xs[0]) / dx).astype(int)
    iy = np.rint((pts[:, 1] - ys[0]) / dy).astype(int)
    slot = ix * ys.size + iy
    if np.unique(slot).size != slot.size:
        return None
    order = np.argsort(slot)
    shape = (xs.size, ys.size)
    H = np.ascontiguousarray(capture.H.reshape(capture.n_bins, -1)[:, order]).reshape(
        capture.n_bins, *shape)
    grid = pts[order].reshape(*shape, 3)
    normals = capture.sensor_grid_normals
    normals = None if normals is None else normals.reshape(-1, 3)[order].reshape(*shape, 3)
    changes: dict[str, Any] = {}
    if capture.kind is CaptureKind.CONFOCAL:
        changes = {"laser_grid_xyz": grid, "laser_grid_normals": normals,
                   "laser_grid_format": GridFormat.X_Y_3}
    return capture.replace(H=H, H_format=HFormat.T_Sx_Sy, sensor_grid_xyz=grid,
                           sensor_grid_normals=normals, sensor_grid_format=GridFormat.X_Y_3,
                           **changes)

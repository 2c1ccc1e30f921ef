"""Phasor fields: complex wavefronts on the relay wall, one per temporal frequency."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.capture.hints import ImagingHints, hints_from
from nlosfw.common.errors import DataError

if TYPE_CHECKING:
    from typing_extensions import Unpack

#: What :meth:`PhasorField.select` takes per axis: an index, a slice, or indices.
Index = int | slice | Sequence[int] | np.ndarray


class FieldChanges(TypedDict, total=False):
    """The attributes :meth:`PhasorField.replace` may replace."""

    values: np.ndarray
    frequencies: np.ndarray
    wall_xyz: np.ndarray
    geometry: CaptureGeometry
    weights: np.ndarray | None
    metadata: dict[str, object]
    variance: np.ndarray | None
    counts: PhotonCounts | None
    band: Band | None
    imaging_hints: ImagingHints | None
    zero_filled: bool
    depth_range: tuple[float, float] | None


#: The metadata keys of fields written before these were typed attributes of
#: :class:`PhasorField` (``band``, ``imaging_hints``, ``zero_filled``, ``depth_range``): a
#: field made with them in its metadata takes them out into the attributes.
LEGACY_KEYS = ("band", "zero_filled", "depth_range")


@dataclass(frozen=True)
class Band:
    """What a transform checked its band against: the wall spacing (None: not checked, an
    irregular wall or a band never imaged on the wall), the highest frequency that does not
    alias there, whether the band passes it, and the option that chose the band (named in
    the aliasing warning)."""

    option: str
    grid_spacing: float | None = None
    spatial_limit: float | None = None
    aliases: bool = False

    def to_dict(self) -> dict[str, object]:
        """Plain values (a field file's YAML)."""
        return {"grid_spacing": self.grid_spacing, "spatial_limit": self.spatial_limit,
                "option": self.option, "aliases": self.aliases}

    @classmethod
    def from_mapping(cls, mapping: object) -> Band | None:
        """The band a field file's mapping records; None for anything else."""
        if not isinstance(mapping, Mapping):
            return None

        def number(key: str) -> float | None:
            value = mapping.get(key)
            if isinstance(value, (int, float)) and not isinstance(value, bool) \
                    and math.isfinite(value) and value > 0:
                return float(value)
            return None

        return cls(option=str(mapping.get("option", "")), grid_spacing=number("grid_spacing"),
                   spatial_limit=number("spatial_limit"), aliases=mapping.get("aliases") is True)


def depth_range_of(value: object) -> tuple[float, float] | None:
    """``value`` as a depth range [near, far] (m, 0 <= near <= far, finite), or None."""
    if (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            and all(math.isfinite(float(v)) for v in value)
            and 0 <= float(value[0]) <= float(value[1])):
        return float(value[0]), float(value[1])
    return None


@dataclass(frozen=True, eq=False)
class PhotonCounts:
    """The photon counts a field was transformed from: ``counts[t, y, x]`` (>= 0, in the
    field's wall layout) in time bins ``delta_t`` metres of path wide, bin i centred at
    ``t_start + (i + 1/2) delta_t`` (the transform's time axis, device legs included when
    the capture's times include them); the capture's H is ``counts / count_scale``."""

    counts: np.ndarray
    t_start: float
    delta_t: float
    count_scale: float = 1.0

    def __post_init__(self) -> None:
        counts = np.asarray(self.counts, dtype=np.float64)
        object.__setattr__(self, "counts", counts)
        if counts.ndim != 3 or counts.shape[0] < 1:
            raise DataError(f"counts: must have shape (time, y, x), got {counts.shape}")
        if not np.all(np.isfinite(counts)) or np.any(counts < 0):
            raise DataError("counts: must be finite photon counts >= 0")
        if not (np.isfinite(self.t_start) and np.isfinite(self.delta_t) and self.delta_t > 0
                and np.isfinite(self.count_scale) and self.count_scale > 0):
            raise DataError(f"counts: need a finite t_start, delta_t > 0 and count_scale > 0, "
                            f"got {self.t_start}, {self.delta_t}, {self.count_scale}")

    def select(self, y: Index = slice(None), x: Index = slice(None)) -> PhotonCounts:
        """The counts of some wall samples (as :meth:`PhasorField.select` takes them)."""
        return dataclasses.replace(self, counts=self.counts[:, y, x])


@dataclass(frozen=True, eq=False)
class PhasorField:
    """Complex field ``values[f, y, x]`` at ``frequencies[f]`` over wall points ``wall_xyz[y, x]``.

    Frequencies are in cycles per metre of optical path (wavelength = 1/f).
    ``weights`` are the spectral weights of the virtual illumination (one per
    frequency; ``None`` means all ones) that an imager applies when it sums
    frequencies. ``geometry`` says how the field was captured. ``variance`` (the values'
    shape, >= 0; ``None``: unknown) is the noise variance of each value, the capture's
    Poisson noise through the transform (:func:`nlosfw.evaluation.noise_floor.field_variance`);
    a fit may weigh samples by it. ``counts`` (``None``: not carried) are the photon counts
    the field was transformed from, at every wall point of the field and every time bin
    (so every frequency, whatever frequencies the field keeps); a fit may take the exact
    Poisson likelihood of them. Neither is written to field files.

    ``band`` is what the transform checked its band against (None: not recorded),
    ``imaging_hints`` the imaging settings the capture states (from the capture), ``zero_filled``
    says the values are training samples on the full grid with zeros elsewhere (the ``raw``
    source of a time-domain imager), and ``depth_range`` [near, far] (m) the run's depths
    of the hidden scene, which bounds a model's own search for it (None: none given).
    ``metadata`` holds anything else (the transform's record of the capture's time axis).

    Scattered wall samples (an irregular scan) are a field with one row: ``wall_xyz``
    (1, N, 3) and ``values`` (F, 1, N); :meth:`grid_spacing` is None for them.
    """

    values: np.ndarray
    frequencies: np.ndarray
    wall_xyz: np.ndarray
    geometry: CaptureGeometry
    weights: np.ndarray | None = None
    metadata: dict[str, object] = field(default_factory=dict)
    variance: np.ndarray | None = None
    counts: PhotonCounts | None = None
    band: Band | None = None
    imaging_hints: ImagingHints | None = None
    zero_filled: bool = False
    depth_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        self._take_legacy_keys()
        values = np.asarray(self.values)
        if not np.iscomplexobj(values):
            values = values.astype(np.complex64)
        set_(self, "values", values)
        set_(self, "frequencies", np.atleast_1d(np.asarray(self.frequencies, dtype=np.float64)))
        set_(self, "wall_xyz", np.asarray(self.wall_xyz, dtype=np.float64))
        if self.weights is not None:
            set_(self, "weights", np.atleast_1d(np.asarray(self.weights, dtype=np.complex128)))
        if self.variance is not None:
            set_(self, "variance", np.asarray(self.variance, dtype=np.float64))
        self._validate()

    def _take_legacy_keys(self) -> None:
        """The typed attributes a metadata mapping written before them holds, moved out of
        it (an attribute given explicitly wins)."""
        set_ = object.__setattr__
        metadata, hints = hints_from(self.metadata or {})
        legacy = {key: metadata.pop(key) for key in LEGACY_KEYS if key in metadata}
        set_(self, "metadata", metadata)
        if self.imaging_hints is None and hints is not None:
            set_(self, "imaging_hints", hints)
        if self.band is None and "band" in legacy:
            set_(self, "band", Band.from_mapping(legacy["band"]))
        if not self.zero_filled and legacy.get("zero_filled") is True:
            set_(self, "zero_filled", True)
        if self.depth_range is None and "depth_range" in legacy:
            set_(self, "depth_range", depth_range_of(legacy["depth_range"]))
        if self.depth_range is not None:
            found = depth_range_of(self.depth_range)
            if found is None:
                raise DataError(f"depth_range: must be [near, far] metres with 0 <= near <= "
                                f"far, got {self.depth_range}")
            set_(self, "depth_range", found)
        set_(self, "zero_filled", bool(self.zero_filled))

    def _validate(self) -> None:
        v, f, w = self.values, self.frequencies, self.wall_xyz
        if v.ndim != 3:
            raise DataError(f"values: must have shape (frequency, y, x), got {v.shape}")
        if f.shape != (v.shape[0],):
            raise DataError(f"frequencies: {f.shape[0]} given for {v.shape[0]} field slices")
        if not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise DataError("frequencies: must be finite and > 0 (cycles per metre)")
        if w.shape != v.shape[1:] + (3,):
            raise DataError(f"wall_xyz: shape {w.shape} does not match the field's "
                            f"(y, x) = {v.shape[1:]} plus 3 coordinates")
        if not np.all(np.isfinite(w)):
            raise DataError("wall_xyz: contains NaN or inf")
        if not np.all(np.isfinite(v)):
            raise DataError("values: contains NaN or inf")
        if self.weights is not None and (
            self.weights.shape != f.shape or not np.all(np.isfinite(self.weights))
        ):
            raise DataError(f"weights: need {f.shape[0]} finite values, got shape "
                            f"{self.weights.shape}")
        var = self.variance
        if var is not None and (var.shape != v.shape or not np.all(np.isfinite(var))
                                or np.any(var < 0)):
            raise DataError(f"variance: must be finite, >= 0 and of the values' shape {v.shape}, "
                            f"got shape {var.shape}")
        if self.counts is not None and self.counts.counts.shape[1:] != v.shape[1:]:
            raise DataError(f"counts: wall layout {self.counts.counts.shape[1:]} is not the "
                            f"values' {v.shape[1:]}")

    @property
    def n_frequencies(self) -> int:
        return int(self.values.shape[0])

    @property
    def grid_shape(self) -> tuple[int, int]:
        """(ny, nx)."""
        return (int(self.values.shape[1]), int(self.values.shape[2]))

    @property
    def effective_weights(self) -> np.ndarray:
        """The weights, or ones when none were given."""
        if self.weights is None:
            return np.ones(self.n_frequencies, dtype=np.complex128)
        return self.weights

    def grid_spacing(self) -> tuple[float, float] | None:
        """(dy, dx) in metres if the wall points form a regular axis-aligned grid, else None."""
        return regular_grid_spacing(self.wall_xyz)

    def select(self, frequency_index: Index = slice(None), y: Index = slice(None),
               x: Index = slice(None)) -> PhasorField:
        """A sub-field: some frequencies and/or a window or stride of wall samples."""
        fi = np.arange(self.n_frequencies)[frequency_index]
        fi = np.atleast_1d(fi)
        values = self.values[fi][:, y, x]
        return dataclasses.replace(
            self,
            values=values,
            frequencies=self.frequencies[fi],
            wall_xyz=self.wall_xyz[y, x],
            weights=None if self.weights is None else self.weights[fi],
            variance=None if self.variance is None else self.variance[fi][:, y, x],
            counts=None if self.counts is None else self.counts.select(y, x),
        )

    def replace(self, **changes: Unpack[FieldChanges]) -> PhasorField:
        """A new field with some attributes replaced (validated again)."""
        return dataclasses.replace(self, **changes)


def regular_grid_spacing(wall_xyz: np.ndarray, rtol: float = 1e-4) -> tuple[float, float] | None:
    """(dy, dx) if ``wall_xyz[y, x]`` is a regular grid in the plane z = 0, else None.

    x must vary along axis 1 and y along axis 0 with constant positive steps.
    A single row or column has spacing 0 along its degenerate axis.
    """
    w = np.asarray(wall_xyz, dtype=float)
    if w.ndim != 3 or w.shape[-1] != 3:
        return None
    scale = max(float(np.ptp(w[..., :2])), 1e-12)
    if np.max(np.abs(w[..., 2])) > rtol * scale:
        return None
    xs, ys = w[0, :, 0], w[:, 0, 1]
    if not (np.allclose(w[..., 0], xs[None, :], atol=rtol * scale)
            and np.allclose(w[..., 1], ys[:, None], atol=rtol * scale)):
        return None
    dx = float(np.mean(np.diff(xs))) if xs.size > 1 else 0.0
    dy = float(np.mean(np.diff(ys))) if ys.size > 1 else 0.0
    if xs.size > 1 and (dx <= 0 or not np.allclose(np.diff(xs), dx, atol=rtol * scale)):
        return None
    if ys.size > 1 and (dy <= 0 or not np.allclose(np.diff(ys), dy, atol=rtol * scale)):
        return None
    return dy, dx

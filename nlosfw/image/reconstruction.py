"""Reconstructions: intensity over a set of voxels in the hidden volume."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import numpy.typing as npt

from nlosfw.common.errors import DataError
from nlosfw.transform.field import PhasorField

if TYPE_CHECKING:
    from typing_extensions import Unpack



class ReconstructionChanges(TypedDict, total=False):
    """The attributes :meth:`Reconstruction.replace` may replace."""

    intensity: np.ndarray
    voxels: np.ndarray
    metadata: dict[str, object]


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """``intensity[...]`` at ``voxels[..., 3]``.

    The voxel set is a plane (Y, X, 3), a stack of planes (Z, Y, X, 3) or any
    points (N, 3); ``intensity`` has the voxel set's shape without the last axis.
    """

    intensity: np.ndarray
    voxels: np.ndarray
    metadata: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "intensity", np.asarray(self.intensity))
        object.__setattr__(self, "voxels", np.asarray(self.voxels, dtype=np.float64))
        object.__setattr__(self, "metadata", dict(self.metadata or {}))
        if self.voxels.shape[-1:] != (3,):
            raise DataError(f"voxels: last axis must hold 3 coordinates, got {self.voxels.shape}")
        if self.intensity.shape != self.voxels.shape[:-1]:
            raise DataError(f"intensity: shape {self.intensity.shape} does not match voxels "
                            f"{self.voxels.shape[:-1]}")
        if np.iscomplexobj(self.intensity) or not np.all(np.isfinite(self.intensity)):
            raise DataError("intensity: must be real and finite")

    @property
    def depths(self) -> np.ndarray:
        """Depth (z) of each plane of a plane or volume reconstruction."""
        if self.intensity.ndim == 2:
            return np.array([float(self.voxels[0, 0, 2])])
        if self.intensity.ndim == 3:
            return self.voxels[:, 0, 0, 2].copy()
        raise DataError("depths: only defined for plane or volume reconstructions")

    def as_volume(self) -> tuple[np.ndarray, np.ndarray]:
        """(intensity (Z, Y, X), voxels (Z, Y, X, 3)) for a plane or a volume."""
        if self.intensity.ndim == 2:
            return self.intensity[None], self.voxels[None]
        if self.intensity.ndim == 3:
            return self.intensity, self.voxels
        raise DataError("reconstruction is a point list, not a plane or a volume")

    def max_intensity_image(self) -> np.ndarray:
        """Maximum over depth, (Y, X)."""
        intensity, _ = self.as_volume()
        return intensity.max(axis=0)

    def depth_map(self, threshold: float = 0.0, refine: bool = False) -> np.ndarray:
        """Depth of the brightest voxel along z for each (y, x), (Y, X).

        Pixels whose maximum is at most ``threshold`` times the global maximum
        are NaN (nothing there). ``refine`` fits a parabola through the peak and
        its two depth neighbours (sub-plane depth; the peak plane's depth at the
        first and last planes).
        """
        intensity, voxels = self.as_volume()
        z = voxels[..., 2]
        best = np.argmax(intensity, axis=0)
        depth = np.take_along_axis(z, best[None], axis=0)[0]
        if refine and intensity.shape[0] >= 3:
            depth = depth + _parabolic_offset(intensity, z, best)
        peak = intensity.max(axis=0)
        return np.where(peak > threshold * float(intensity.max()), depth, np.nan)

    def depth_and_max_images(self, threshold: float = 0.0,
                             refine: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(depth map, max-intensity image), both (Y, X): the usual 2-D summary of a volume."""
        return self.depth_map(threshold, refine), self.max_intensity_image()

    def replace(self, **changes: Unpack[ReconstructionChanges]) -> Reconstruction:
        """A new reconstruction with some attributes replaced (validated again)."""
        return dataclasses.replace(self, **changes)


def _parabolic_offset(intensity: np.ndarray, z: np.ndarray, best: np.ndarray) -> np.ndarray:
    """Depth offset of the vertex of the parabola through planes best-1, best, best+1."""
    n = intensity.shape[0]
    inner = np.clip(best, 1, n - 2)[None]
    y0, y1, y2 = (np.take_along_axis(intensity, inner + k, axis=0)[0] for k in (-1, 0, 1))
    z0, z2 = (np.take_along_axis(z, inner + k, axis=0)[0] for k in (-1, 1))
    curvature = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(curvature < 0, 0.5 * (y0 - y2) / curvature, 0.0)
    shift = np.clip(np.nan_to_num(shift), -0.5, 0.5) * (z2 - z0) / 2
    edge = (best == 0) | (best == n - 1)
    return np.where(edge, 0.0, shift)


def plane_voxels(depth: float, x_range: tuple[float, float], y_range: tuple[float, float],
                 shape: tuple[int, int]) -> np.ndarray:
    """A plane parallel to the wall at ``depth``, cell-centred samples, shape (Y, X, 3)."""
    return volume_voxels([depth], x_range, y_range, shape)[0]


def volume_voxels(depths: npt.ArrayLike, x_range: tuple[float, float], y_range: tuple[float, float],
                  shape: tuple[int, int]) -> np.ndarray:
    """A stack of planes parallel to the wall, shape (Z, Y, X, 3).

    ``shape`` is (ny, nx); samples are cell-centred in the given ranges.
    """
    depths = np.atleast_1d(np.asarray(depths, dtype=float))
    ny, nx = shape
    xs = cell_centres(x_range, nx)
    ys = cell_centres(y_range, ny)
    z, y, x = np.meshgrid(depths, ys, xs, indexing="ij")
    return np.stack([x, y, z], axis=-1)


def cell_centres(bounds: tuple[float, float], n: int) -> np.ndarray:
    """``n`` cell-centred samples between ``bounds[0]`` and ``bounds[1]``."""
    lo, hi = float(bounds[0]), float(bounds[1])
    step = (hi - lo) / n
    return lo + (np.arange(n) + 0.5) * step


def wall_voxels(field: PhasorField, depths: npt.ArrayLike) -> np.ndarray:
    """Planes at ``depths`` (m) on the wall grid of ``field``, shape (Z, Y, X, 3).

    The planes span the wall's grid cells (each voxel faces one wall sample), as every
    run images them; a field whose wall samples are not a regular grid gets a DataError.
    """
    depths = np.atleast_1d(np.asarray(depths, dtype=float))
    if depths.ndim != 1 or depths.size == 0 or not np.all(np.isfinite(depths) & (depths > 0)):
        raise DataError(f"depths: need one or more finite depths > 0 (m, in front of the "
                        f"wall), got {np.asarray(depths).tolist()}")
    spacing = field.grid_spacing()
    if spacing is None:
        raise DataError("field: its wall samples are not a regular grid; give explicit voxels "
                        "to an imager that accepts points")
    dy, dx = spacing
    ny, nx = field.grid_shape
    wall = field.wall_xyz
    x0, y0 = wall[0, 0, 0] - dx / 2, wall[0, 0, 1] - dy / 2
    return volume_voxels(depths, (x0, x0 + nx * dx), (y0, y0 + ny * dy), (ny, nx))

"""What the phasor-field imagers share: options, checks, frequency sums, the result.

An imager propagates every frequency of the field to the voxels (U_f, see
:mod:`nlosfw.image.rsd_kernel`) and combines them:

* ``coherent`` (default): I(x_v) = |sum_f c_f U_f(x_v)|^2 with
  c_f = w_f * exp(2 pi i f t), w_f the field's spectral weights (ones when the
  field has none) and t the virtual time (``time``, metres of path; 0 gives the
  usual t = 0 image of Liu's virtual illumination);
* ``incoherent``: I(x_v) = sum_f |w_f U_f(x_v)|^2 (independent of t).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np
import numpy.typing as npt

from nlosfw.common.config import Choice, require
from nlosfw.common.errors import DataError
from nlosfw.common.progress import ProgressCallback
from nlosfw.image.interface import Imager, ImagerConfig
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.rsd_kernel import check_geometry
from nlosfw.transform.field import Index, PhasorField
from nlosfw.transform.temporal_dft import unit_phasor


class Combine(Choice):
    """How the frequencies' propagated fields make one image (see the module docstring)."""

    coherent = "coherent"
    incoherent = "incoherent"


@dataclass(frozen=True)
class PropagationConfig(ImagerConfig):
    """Options shared by the ``rsd`` and ``fft`` imagers."""

    combine: Combine = Combine.coherent
    """``coherent``: |sum_f w_f U_f|^2; ``incoherent``: sum_f |w_f U_f|^2."""
    time: float = 0.0
    """[m] Virtual time (a path length) of the coherent image; 0 images the pulse as it
    focuses."""

    def __post_init__(self) -> None:
        require(np.isfinite(self.time), "time", f"must be a finite number, got {self.time}")


def check_voxels(voxels: npt.ArrayLike) -> np.ndarray:
    """Voxels as float64 (..., 3) in front of the wall; DataError otherwise."""
    v = np.asarray(voxels, dtype=np.float64)
    if v.ndim not in (2, 3, 4) or v.shape[-1] != 3:
        raise DataError(f"voxels: expected a plane (Y, X, 3), planes (Z, Y, X, 3) or points "
                        f"(N, 3), got shape {v.shape}")
    if v.size == 0:
        raise DataError(f"voxels: the voxel set is empty (shape {v.shape})")
    if not np.all(np.isfinite(v)):
        raise DataError("voxels: contain NaN or inf")
    z_min = float(v[..., 2].min())
    if z_min <= 0:
        raise DataError(f"voxels: z must be > 0 (in front of the relay wall at z = 0); got "
                        f"min z = {z_min:.6g} m")
    return v


def check_field(field: Any) -> PhasorField:
    """The field, if an imager can use it; DataError otherwise."""
    if not isinstance(field, PhasorField):
        raise DataError(f"field: expected a PhasorField, got {type(field).__name__}")
    check_geometry(field.geometry)
    return field


def coefficients(field: PhasorField, times: np.ndarray) -> np.ndarray:
    """c[t, f] = w_f exp(+2 pi i f t) for the virtual times ``times`` (m of path)."""
    times = np.atleast_1d(np.asarray(times, dtype=float))
    return field.effective_weights[None, :] * unit_phasor(
        times[:, None] * field.frequencies[None, :])


class FrequencySum:
    """Accumulates sum_f c[t, f] U_f (coherent) or sum_f |c[t, f] U_f|^2 over batches."""

    def __init__(self, coeffs: np.ndarray, combine: Combine, shape: tuple[int, ...]) -> None:
        self.coeffs = coeffs
        self.coherent = combine == "coherent"
        dtype = np.complex128 if self.coherent else np.float64
        self.acc = np.zeros((coeffs.shape[0],) + tuple(shape), dtype=dtype)

    def add(self, fields: np.ndarray, index: Index = slice(None)) -> None:
        """Add U_f for the frequencies ``index`` (fields: (n_f, *shape))."""
        c = self.coeffs[:, index]
        # einsum, not a BLAS product: these are matrix-vector sized (one row per time).
        if self.coherent:
            self.acc += np.einsum("tf,f...->t...", c, fields)
        else:
            power = fields.real**2 + fields.imag**2
            self.acc += np.einsum("tf,f...->t...", np.abs(c) ** 2, power)

    def add_amplitude(self, amplitude: np.ndarray) -> None:
        """Add an already combined coherent amplitude (n_t, *shape)."""
        self.acc += amplitude

    def intensity(self) -> np.ndarray:
        """The image(s), (n_t, *shape), real."""
        if self.coherent:
            return self.acc.real**2 + self.acc.imag**2
        return self.acc.copy()


PropagationConfigT = TypeVar("PropagationConfigT", bound=PropagationConfig)


class PropagationImager(Imager[PropagationConfigT]):
    """Base of the imagers that propagate each frequency with the shared RSD kernel."""

    config_class: ClassVar[type] = PropagationConfig
    imager_name: ClassVar[str] = "propagation"

    def reconstruct(self, field: PhasorField, voxels: np.ndarray,
                    on_progress: ProgressCallback | None = None) -> Reconstruction:
        """Intensity at ``voxels`` (plane, planes or points) at virtual time ``config.time``;
        ``on_progress(done, total)`` after each block of voxels (see :class:`Imager`)."""
        field = check_field(field)
        voxels = self.check_voxels(check_voxels(voxels), field)
        coeffs = coefficients(field, np.array([self.config.time]))
        intensity = self._intensity(field, voxels, coeffs, on_progress)[0]
        meta = self._metadata(field, voxels)  # no wall-clock time: same field, same bytes
        return Reconstruction(intensity=intensity, voxels=voxels, metadata=meta)

    def reconstruct_time_resolved(self, field: PhasorField, voxels: np.ndarray,
                                  times: npt.ArrayLike) -> np.ndarray:
        """Intensities (n_times, *voxels.shape[:-1]) at several virtual times (m of path).

        Time t images the virtual pulse t metres of path after it focuses at the
        voxel (coherent combination; ``incoherent`` gives the same image at every t).
        """
        field = check_field(field)
        voxels = self.check_voxels(check_voxels(voxels), field)
        times = np.atleast_1d(np.asarray(times, dtype=float))
        if times.ndim != 1 or times.size == 0 or not np.all(np.isfinite(times)):
            raise DataError(f"times: need a non-empty 1-D list of finite times, got shape "
                            f"{times.shape}")
        return self._intensity(field, voxels, coefficients(field, times))

    def check_voxels(self, voxels: np.ndarray, field: PhasorField) -> np.ndarray:
        """Imager-specific voxel checks (default: none)."""
        return voxels

    @abstractmethod
    def _intensity(self, field: PhasorField, voxels: np.ndarray, coeffs: np.ndarray,
                   on_progress: ProgressCallback | None = None) -> np.ndarray:
        """Images (n_t, *voxels.shape[:-1]) for coefficient rows ``coeffs`` (n_t, F),
        reporting finished blocks to ``on_progress``
        (:class:`~nlosfw.common.progress.ProgressCounter` counts them)."""

    def _metadata(self, field: PhasorField, voxels: np.ndarray) -> dict[str, object]:
        return {
            "imager": self.imager_name,
            "frequencies": [float(f) for f in field.frequencies],
            "weighted": field.weights is not None,
            "combine": self.config.combine,
            "time": float(self.config.time),
            "capture_kind": field.geometry.kind.value,
            "device_legs_in_field": bool(field.geometry.t_accounts_first_and_last_bounces),
            "n_voxels": int(np.prod(voxels.shape[:-1])),
        }

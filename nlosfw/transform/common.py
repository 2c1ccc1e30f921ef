"""What the phasor transforms share: capture checks, wall layout, device legs.

Layout: ``H`` is [t, x, y] (y-tal's T_Sx_Sy, ``sensor_grid_xyz`` (X, Y, 3)),
a :class:`~nlosfw.transform.PhasorField` is [frequency, y, x] with
``wall_xyz`` (Y, X, 3). A sensor list (T_Si, ``N_3``) becomes a field of one
row: values (F, 1, N), wall_xyz (1, N, 3).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind, GridFormat
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.transform.field import Band, PhasorField
from nlosfw.transform.temporal_dft import temporal_dft, unit_phasor


def check_capture(capture: Capture, transform: str) -> None:
    """DataError unless ``capture`` is a time-domain single-spot or confocal capture."""
    if not isinstance(capture, Capture):
        raise DataError(f"the {transform} transform needs a Capture, got {type(capture).__name__}")
    if not capture.is_time_domain:
        raise DataError(f"H_format: {capture.H_format.name} is in the frequency domain; the "
                        f"{transform} transform needs a time-domain capture (T_Sx_Sy or T_Si)")
    if capture.kind is CaptureKind.EXHAUSTIVE:
        raise DataError(f"H_format: {capture.H_format.name} is an exhaustive capture; the "
                        f"{transform} transform supports single-spot and confocal captures only")
    if np.iscomplexobj(capture.H):
        raise DataError(f"H: dtype {capture.H.dtype} is complex in a time-domain capture; the "
                        f"{transform} transform needs real histograms (float32 or float64)")


def wall_points(capture: Capture) -> np.ndarray:
    """The sensor points as the field's wall grid (Y, X, 3) (or (1, N, 3) for a list)."""
    grid = np.asarray(capture.sensor_grid_xyz, dtype=float)
    if capture.sensor_grid_format is GridFormat.X_Y_3:
        return np.ascontiguousarray(grid.transpose(1, 0, 2))
    return grid.reshape(1, -1, 3)


def histogram_2d(capture: Capture) -> np.ndarray:
    """H as (T, S), sensors in the order of ``capture.sensor_points`` (a view when possible)."""
    return capture.H.reshape(capture.n_bins, -1)


def to_field_layout(values: np.ndarray, capture: Capture) -> np.ndarray:
    """(F, S) in sensor order -> (F, Y, X) of the field (a contiguous copy)."""
    n_f = values.shape[0]
    if capture.sensor_grid_format is GridFormat.X_Y_3:
        nx, ny = capture.sensor_grid_xyz.shape[:2]
        return np.ascontiguousarray(values.reshape(n_f, nx, ny).transpose(0, 2, 1))
    return values.reshape(n_f, 1, -1)


@dataclass(frozen=True, eq=False)
class FieldOptions:
    """How :func:`transform_capture` makes a field: the transform's name (recorded in the
    field's metadata), its DFT method, whether to remove the device legs, and the field's
    spectral weights, band and extra metadata."""

    transform: str
    method: str
    remove_device_legs: bool
    weights: np.ndarray | None = None
    metadata: Mapping[str, object] = dataclasses.field(default_factory=dict)
    band: Band | None = None


def transform_capture(capture: Capture, frequencies: np.ndarray,
                      options: FieldOptions) -> PhasorField:
    """The phasor field of ``capture`` at ``frequencies`` (already validated).

    P_f(x_s) = sum_t H(x_s, t) exp(-2 pi i f t_c) delta_t, t_c the bin centres.
    If the time axis includes the device legs and ``options.remove_device_legs`` is
    true, each sensor's field is multiplied by exp(+2 pi i f device_path(x_s)),
    and the field's geometry says the legs are gone.
    """
    method, remove_device_legs = options.method, options.remove_device_legs
    f = np.asarray(frequencies, dtype=np.float64)
    try:
        flat, used = temporal_dft(histogram_2d(capture), capture.t_start, capture.delta_t, f,
                                  method)
    except ConfigError as err:
        raise err.within("transform") from None
    geometry = capture.geometry
    removed = bool(remove_device_legs and geometry.t_accounts_first_and_last_bounces)
    if removed:
        legs = geometry.device_path(capture.sensor_points)
        for i in range(f.size):
            flat[i] *= unit_phasor(f[i] * legs)
        geometry = dataclasses.replace(geometry, t_accounts_first_and_last_bounces=False)
    values = to_field_layout(flat, capture)
    del flat
    info: dict[str, object] = {
        "transform": options.transform,
        "method": used,
        "capture_kind": capture.kind.value,
        "n_bins": capture.n_bins,
        "delta_t": float(capture.delta_t),
        "t_start": float(capture.t_start),
        "device_legs_in_capture": bool(capture.t_accounts_first_and_last_bounces),
        "device_legs_removed": removed,
    }
    info.update(options.metadata)  # no wall-clock time: same capture, same bytes
    return PhasorField(values=values, frequencies=f, wall_xyz=wall_points(capture),
                       geometry=geometry, weights=options.weights, metadata=info,
                       band=options.band, imaging_hints=capture.imaging_hints)

"""The variance a capture's Poisson noise adds to its phasor field, through any DFT-like
transform.

A linear transform gives P(x, f) = sum_t K(f, t) H(x, t). Independent bins of variance
v(x, t) give Var P(x, f) = sum_t |K(f, t)|^2 v(x, t). For the temporal DFT of every nlosfw
transform (``fft``, ``wavelet``: K = exp(-2 pi i f t_c) delta_t, times a unit phasor for the
device legs) |K|^2 = delta_t^2 at every t, so Var P(x, f) = delta_t^2 sum_t v(x, t); for
Poisson counts v = n.

:func:`field_variance` finds |K(f, t)|^2 by probing the transform itself, so a third-party
transform works too when it is of this kind: an impulse at a different time bin at every
scan point must give one magnitude per frequency at every point, and twice the probe
must give twice the field (linear). A transform that fails the probe is refused for
``split.count_splitting`` (its noise floor is not computed from counts this way).
"""

from __future__ import annotations

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.photon_counts import count_variance
from nlosfw.common.errors import ConfigError
from nlosfw.evaluation.count_splitting import OPTION
from nlosfw.transform.common import histogram_2d, to_field_layout
from nlosfw.transform.field import PhasorField
from nlosfw.transform.interface import PhasorTransform

#: The built-in transforms, plain temporal DFTs (the pre-run check probes any other).
DFT_TRANSFORMS = ("fft", "wavelet")

#: Relative spread of |K|^2 over time allowed by the probe (round-off of an exact DFT).
_RTOL = 1e-6


def kernel_power(transform: PhasorTransform, capture: Capture, name: str = "transform",
                 option: str = OPTION, purpose: str = "count splitting") -> np.ndarray:
    """|K(f, t)|^2 per frequency (F,) of ``transform`` on captures laid out as ``capture``,
    probed with impulses; a ConfigError for ``option`` (the step that needs it,
    ``purpose``) when it is not linear or its kernel's magnitude changes with time."""
    n_bins = capture.n_bins
    n_points = int(np.prod(capture.H.shape[1:]))
    bins = np.linspace(0, n_bins - 1, n_points).round().astype(np.int64)
    probe = np.zeros((n_bins, n_points), dtype=np.float64)
    probe[bins, np.arange(n_points)] = 1.0
    one = _values(transform, capture, probe)
    two = _values(transform, capture, 2.0 * probe)
    power = np.abs(one) ** 2                                    # (F, points)
    scale = np.max(power, axis=1, keepdims=True)
    if not np.all(np.isfinite(power)) or np.any(scale <= 0):
        raise ConfigError(option, f"the {name} transform gives no finite, nonzero response to "
                                  "an impulse: its noise floor cannot be computed; use the fft "
                                  f"or wavelet transform with {purpose}")
    if not np.allclose(two, 2.0 * one, rtol=_RTOL, atol=_RTOL * float(np.sqrt(scale.max()))):
        raise ConfigError(option, f"the {name} transform is not linear in H: its noise floor "
                                  "cannot be computed from counts; use the fft or wavelet "
                                  f"transform with {purpose}")
    spread = float(np.max((power.max(axis=1) - power.min(axis=1)) / scale[:, 0]))
    if spread > _RTOL:
        raise ConfigError(option, f"the {name} transform weighs time bins unequally (|kernel|^2 "
                              f"varies by {spread:.2g} over time): the noise floor is computed "
                              "for DFT-like transforms only; use the fft or wavelet transform "
                              f"with {purpose}")
    return np.asarray(power.mean(axis=1))


def field_variance(transform: PhasorTransform, capture: Capture, name: str = "transform",
                   option: str = OPTION, purpose: str = "count splitting",
                   power: np.ndarray | None = None) -> np.ndarray:
    """Var P(f, y, x) of the phasor field of ``capture`` (Poisson counts, their variance
    estimated by themselves), in the field's layout (F, Y, X); errors as
    :func:`kernel_power`'s. ``power``: :func:`kernel_power`'s result for a capture of this
    layout, when it was probed already (the probe is two transforms of the capture's size)."""
    if power is None:
        power = kernel_power(transform, capture, name, option, purpose)
    per_point = histogram_2d(capture.replace(H=count_variance(capture))).sum(axis=0)
    layout = to_field_layout(per_point[np.newaxis, :], capture)        # (1, Y, X)
    return power[:, np.newaxis, np.newaxis] * layout


def _values(transform: PhasorTransform, capture: Capture, flat: np.ndarray) -> np.ndarray:
    """The transform's field of ``flat`` (T, points) laid out as ``capture``, as (F, points)."""
    field: PhasorField = transform.transform(capture.replace(H=flat.reshape(capture.H.shape)))
    return np.asarray(field.values).reshape(field.values.shape[0], -1)

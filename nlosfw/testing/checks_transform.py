"""Conformance checks for every transform plugin (see :mod:`nlosfw.testing.checks_common`).

Every check builds captures with the analytic simulator on a NON-square wall
(8 x 6 sensors, so a transposition cannot hide) and compares the plugin's field
with physics or with the brute-force references of :mod:`nlosfw.testing.reference`:

* layout: values [frequency, y, x], wall_xyz (Y, X, 3), one sensor's impulse
  lands on that sensor only, single-spot and confocal;
* the field equals the brute-force DFT P_f = sum_t H exp(-2 pi i f t_c) delta_t at
  the field's own frequencies (1e-6 relative), device legs accounted for;
* linearity in H;
* a point scatterer's phase is -2 pi f x (its analytic path length), within
  half a time bin, with and without device legs in the capture;
* exhaustive captures are refused with a one-line DataError;
* ``any_frequencies``: the field holds exactly the requested frequencies, off the
  DFT bins too, with the brute-force DFT's values;
* ``spectral_weights``: the weights are the spectrum of a pulse centred at t = 0;
* ``gaussian_wavelet``: the weights equal the spectrum of the Gaussian kernel that
  the ``WaveletTransformConfig`` options describe.

The capture-dependent checks run once per geometry the transform declares
(``single_spot``, ``confocal``).
"""

from __future__ import annotations

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.common.errors import DataError
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import fixtures, reference
from nlosfw.testing.checks_common import one_line_error
from nlosfw.testing.selection import GEOMETRIES, requires
from nlosfw.transform.field import PhasorField

#: Target of the point-scatterer captures (m); off-centre so no symmetry hides errors.
TARGET = (0.1, -0.05, 0.5)
#: Sensor spacing of the fixtures (m): 0.8 x 0.6 m wall, 8 x 6 sensors.
SPACING = 0.1


def _transform(spec: PluginSpec, capture: Capture, **options: object) -> PhasorField:
    field = spec.create({**spec.test_config, **options}).transform(capture)
    assert field.values.ndim == 3, f"{spec.qualified_name}: values must be (F, Y, X)"
    return field


def _max_rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@requires(each=GEOMETRIES)
def check_transform_layout(spec: PluginSpec, confocal: bool) -> None:
    """Field layout [f, y, x]: an impulse at sensor (x=5, y=1) appears at values[:, 1, 5] only."""
    capture = fixtures.point_capture(confocal=confocal)
    H = np.zeros_like(capture.H)
    H[137, 5, 1] = 1.0
    field = _transform(spec, capture.replace(H=H))
    n_f = field.n_frequencies
    assert field.values.shape == (n_f, 6, 8), (
        f"{spec.qualified_name}: values shape {field.values.shape}, expected (F, 6, 8) for "
        "H of shape (T, X=8, Y=6)")
    np.testing.assert_allclose(field.wall_xyz, capture.sensor_grid_xyz.transpose(1, 0, 2),
                               atol=1e-12, err_msg="wall_xyz must be sensor_grid_xyz "
                               "transposed to (Y, X, 3)")
    assert field.geometry.kind is capture.kind, "the field must keep the capture kind"
    peak = np.abs(field.values[:, 1, 5])
    rest = np.abs(field.values).copy()
    rest[:, 1, 5] = 0
    assert np.all(peak > 0.5 * capture.delta_t), (
        f"{spec.qualified_name}: the impulse at sensor x=5, y=1 is not at values[:, 1, 5] "
        f"(confocal={confocal})")
    assert rest.max() <= 1e-9 * peak.max(), (
        f"{spec.qualified_name}: an impulse at one sensor leaked to other wall samples")


@requires(each=GEOMETRIES)
def check_transform_matches_bruteforce_dft(spec: PluginSpec, confocal: bool) -> None:
    """Values equal the brute-force DFT at the field's frequencies, 1e-6 relative, with and
    without device legs in the capture."""
    for legs in (False, True):
        capture = fixtures.random_capture(seed=3, confocal=confocal, device_legs=legs)
        field = _transform(spec, capture)
        expected = reference.naive_capture_field(capture, field.frequencies)
        wall = capture.sensor_grid_xyz.transpose(1, 0, 2)
        removed = (reference.device_legs(capture.geometry, wall)
                   - reference.device_legs(field.geometry, wall))
        expected = expected * np.exp(2j * np.pi * field.frequencies[:, None, None] * removed)
        err = _max_rel(field.values, expected)
        assert err <= 1e-6, (
            f"{spec.qualified_name}: differs from the brute-force DFT by {err:.3g} (relative, "
            f"confocal={confocal}, device legs={legs}); expected <= 1e-6")


@requires(each=GEOMETRIES)
def check_transform_linearity(spec: PluginSpec, confocal: bool) -> None:
    """transform(a H + b G) = a transform(H) + b transform(G)."""
    capture = fixtures.random_capture(seed=1, confocal=confocal)
    G = np.random.default_rng(2).standard_normal(capture.H.shape).astype(np.float32)
    a, b = 1.75, -0.5
    combined = _transform(spec, capture.replace(H=(a * capture.H + b * G).astype(np.float32)))
    separate = (a * _transform(spec, capture).values
                + b * _transform(spec, capture.replace(H=G)).values)
    err = _max_rel(combined.values, separate)
    assert err <= 1e-5, (f"{spec.qualified_name}: not linear in H (relative error {err:.3g}, "
                         f"confocal={confocal})")


@requires(each=GEOMETRIES)
def check_transform_point_phase(spec: PluginSpec, confocal: bool) -> None:
    """A point scatterer's phase is -2 pi f (its analytic path), within half a time bin,
    with and without device legs in the capture."""
    p = np.asarray(TARGET)
    for legs in (False, True):
        capture = fixtures.point_capture(target=TARGET, confocal=confocal, device_legs=legs)
        field = _transform(spec, capture)
        wall = capture.sensor_grid_xyz.transpose(1, 0, 2)                  # (Y, X, 3)
        r_s = np.linalg.norm(wall - p, axis=-1)
        r_l = r_s if confocal else np.full_like(r_s, np.linalg.norm(p))   # laser at the centre
        path = r_l + r_s + reference.device_legs(field.geometry, wall)
        f = field.frequencies[:, None, None]
        residual = np.angle(field.values * np.exp(2j * np.pi * f * path[None]))
        limit = np.pi * f * capture.delta_t + 1e-6
        worst = float(np.max(np.abs(residual) - limit))
        assert worst <= 0, (
            f"{spec.qualified_name}: point-scatterer phase is off the analytic path length by "
            f"more than half a bin (excess {worst:.3g} rad, confocal={confocal}, legs={legs})")
        amplitude = capture.H.sum(axis=0).T * capture.delta_t              # one bin per sensor
        err = _max_rel(np.abs(field.values), np.broadcast_to(amplitude, field.values.shape))
        assert err <= 1e-6, f"{spec.qualified_name}: |P| != H * delta_t (relative {err:.3g})"


def check_transform_refuses_exhaustive(spec: PluginSpec) -> None:
    """An exhaustive capture (every laser point with every sensor) gives a one-line DataError."""
    plugin = spec.create(dict(spec.test_config))
    one_line_error(spec, "an exhaustive capture (a PhasorField cannot hold its laser axis)",
                   lambda: plugin.transform(fixtures.exhaustive_capture()), DataError)


@requires(Capability.ANY_FREQUENCIES, any_of=GEOMETRIES)
def check_transform_at_requested_frequencies(spec: PluginSpec, confocal: bool) -> None:
    """Option ``frequencies``: the field holds exactly those (off the DFT bins too, in the
    order given), with the brute-force DFT's values (1e-6 relative)."""
    requested = (3.3, 2.05, 4.71, 1.234)
    capture = fixtures.random_capture(seed=5, confocal=confocal)
    field = _transform(spec, capture, frequencies=requested)
    np.testing.assert_array_equal(field.frequencies, np.asarray(requested), err_msg=(
        f"{spec.qualified_name}: asked for frequencies {requested}, got {field.frequencies}"))
    expected = reference.naive_capture_field(capture, field.frequencies)
    err = _max_rel(field.values, expected)
    assert err <= 1e-6, (
        f"{spec.qualified_name}: at the requested frequencies the field differs from the "
        f"brute-force DFT by {err:.3g} (relative, confocal={confocal}); expected <= 1e-6")


@requires(Capability.SPECTRAL_WEIGHTS, any_of=GEOMETRIES)
def check_weights_form_centred_pulse(spec: PluginSpec, confocal: bool) -> None:
    """The weights w_f are a virtual illumination: finite, one per frequency, and the pulse
    |sum_f w_f exp(2 pi i f t)| they describe peaks at t = 0 (within one time bin) over
    the capture's window, so the t = 0 image is the focused one."""
    capture = fixtures.point_capture(confocal=confocal)
    field = _transform(spec, capture)
    assert field.weights is not None, (
        f"{spec.qualified_name}: declares spectral_weights but its field has no weights")
    w = np.asarray(field.weights)
    assert w.shape == field.frequencies.shape and np.all(np.isfinite(w)) and np.any(w != 0), (
        f"{spec.qualified_name}: weights must be finite, not all zero, one per frequency; "
        f"got shape {w.shape} for {field.n_frequencies} frequencies")
    half = capture.n_bins * capture.delta_t / 2
    t = np.linspace(-half, half, 4 * capture.n_bins + 1)
    pulse = np.abs(np.exp(2j * np.pi * t[:, None] * field.frequencies[None]) @ w)
    peak = float(t[np.argmax(pulse)])
    assert abs(peak) <= capture.delta_t, (
        f"{spec.qualified_name}: the illumination pulse of the weights peaks at t = "
        f"{peak:.4g} m, not at 0 (within one bin, {capture.delta_t} m)")


@requires(Capability.GAUSSIAN_WAVELET, any_of=GEOMETRIES)
def check_wavelet_weights_are_kernel_spectrum(spec: PluginSpec, confocal: bool) -> None:
    """Gaussian-wavelet weights are df times the spectrum of K(t), over f_c ± sigma_range sigma_f.

    K(t) is the kernel that the ``WaveletTransformConfig`` options describe (the config
    must derive from it); the spectrum is integrated numerically from K(t), not from a
    closed form.
    """
    from nlosfw.transform.wavelet import WaveletTransformConfig

    config = spec.make_config(dict(spec.test_config))
    assert isinstance(config, WaveletTransformConfig), (
        f"{spec.qualified_name}: declares gaussian_wavelet, so its config must derive from "
        f"WaveletTransformConfig (the kernel's options); got {type(config).__name__}")
    field = _transform(spec, fixtures.point_capture(confocal=confocal))
    spacing = SPACING if config.grid_spacing is None else config.grid_spacing
    wavelength = config.wavelength or config.wavelength_factor * spacing
    sigma = config.n_cycles * wavelength / 6
    f = np.sort(field.frequencies)
    assert field.weights is not None, f"{spec.qualified_name}: a wavelet field needs weights"
    df = float(np.mean(np.diff(f))) if f.size > 1 else 0.0
    assert f.size > 1 and np.allclose(np.diff(f), df, rtol=1e-9), "bins must be equally spaced"
    sigma_f = 1 / (2 * np.pi * sigma)
    lo, hi = 1 / wavelength - config.sigma_range * sigma_f, 1 / wavelength + config.sigma_range \
        * sigma_f
    assert lo - 1e-9 <= f[0] < lo + df and hi - df < f[-1] <= hi + 1e-9, (
        f"{spec.qualified_name}: bins {f[0]:.4g}..{f[-1]:.4g} do not cover exactly "
        f"f_c ± {config.sigma_range} sigma_f = {lo:.4g}..{hi:.4g}")
    expected = df * reference.gaussian_pulse_spectrum(field.frequencies, wavelength, sigma)
    err = _max_rel(field.weights, expected)
    assert err <= 1e-6, f"{spec.qualified_name}: weights differ from df * K^(f) by {err:.3g}"


TRANSFORM_CHECKS = (
    check_transform_layout,
    check_transform_matches_bruteforce_dft,
    check_transform_linearity,
    check_transform_point_phase,
    check_transform_refuses_exhaustive,
    check_transform_at_requested_frequencies,
    check_weights_form_centred_pulse,
    check_wavelet_weights_are_kernel_spectrum,
)

"""The built-in phasor transforms ``fft`` and ``wavelet``.

The generic properties (layout, brute-force DFT, linearity, point phase) are
conformance checks run on every transform plugin; here are the options, the
frequency bands, the limits and the memory behaviour of the built-ins.
"""

from __future__ import annotations

import logging
import tracemalloc

import numpy as np
import pytest

from nlosfw.api import transform_capture
from nlosfw.capture.data import Capture
from nlosfw.capture.enums import GridFormat, HFormat
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.testing import fixtures, reference
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.frequencies import band_warning, dft_length, grid_spacing
from nlosfw.transform.temporal_dft import temporal_dft
from nlosfw.transform.wavelet import WaveletTransform

SPACING = 0.1   # of fixtures.point_capture: 0.8 x 0.6 m wall, 8 x 6 sensors


def test_default_band_is_two_to_eight_grid_spacings():
    capture = fixtures.point_capture()
    field = FFTTransform().transform(capture)
    assert field.n_frequencies == 151
    assert field.frequencies[-1] == pytest.approx(1 / (2 * SPACING))     # finest wavelength 2Δ
    assert field.frequencies[0] == pytest.approx(1 / (8 * SPACING))      # longest 8Δ
    assert np.allclose(np.diff(field.frequencies), np.diff(field.frequencies)[0])
    assert field.weights is None


def test_default_band_is_capped_at_the_temporal_nyquist_limit():
    capture = fixtures.point_capture(bins=30, bin_width=0.15)           # Nyquist 3.33 < 5
    field = FFTTransform({"n_frequencies": 5}).transform(capture)
    assert field.frequencies[-1] == pytest.approx(1 / (2 * 0.15))


def test_explicit_frequencies_are_used_as_given():
    freqs = (3.3, 1.25, 4.0)
    field = FFTTransform({"frequencies": list(freqs)}).transform(fixtures.point_capture())
    np.testing.assert_array_equal(field.frequencies, freqs)


def test_frequency_above_temporal_nyquist_is_a_one_line_error():
    capture = fixtures.point_capture()                                   # delta_t 0.01: 50
    with pytest.raises(ConfigError) as err:
        FFTTransform({"frequencies": [2.0, 60.0]}).transform(capture)
    text = str(err.value)
    assert "\n" not in text and "60" in text and "50" in text and "frequencies" in text


@pytest.mark.parametrize("options, option", [
    ({"frequencies": [0.0]}, "frequencies"),
    ({"frequencies": [-2.0]}, "frequencies"),
    ({"frequencies": [float("inf")]}, "frequencies"),
    ({"f_min": 5.0, "f_max": 2.0}, "f_min"),
    ({"f_max": -1.0}, "f_max"),
    ({"n_frequencies": 0}, "n_frequencies"),
    ({"frequencies": [2.0], "f_max": 4.0}, "frequencies"),
    ({"grid_spacing": 0.0}, "grid_spacing"),
])
def test_bad_frequency_options_are_rejected(options, option):
    with pytest.raises(ConfigError) as err:
        FFTTransform(options)
    assert option in str(err.value) and "\n" not in str(err.value)


def test_empty_band_against_the_capture_is_an_error():
    with pytest.raises(ConfigError, match="empty band"):
        FFTTransform({"f_min": 7.0}).transform(fixtures.point_capture())  # f_max = 5


def test_aliasing_is_recorded_in_the_band_not_an_error(caplog):
    """The transform records whether its band aliases on the wall grid; whoever images the
    field on the wall says it (a run, once; the Python API's transform_capture)."""
    capture = fixtures.point_capture()
    with caplog.at_level(logging.WARNING):
        fine = FFTTransform({"n_frequencies": 4}).transform(capture)
        aliasing = FFTTransform({"frequencies": [8.0]}).transform(capture)  # 1/8 m < 2 * 0.1 m
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not fine.band.aliases and band_warning(fine) is None
    assert aliasing.band.aliases
    assert "alias" in band_warning(aliasing) and "0.1" in band_warning(aliasing)
    with caplog.at_level(logging.WARNING):
        transform_capture(capture, "fft", frequencies=[8.0])
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert warnings == [band_warning(aliasing)]


def test_grid_spacing_option_sets_the_band_for_a_denser_grid():
    field = FFTTransform({"grid_spacing": 0.05, "n_frequencies": 3}).transform(
        fixtures.point_capture())
    assert field.frequencies[-1] == pytest.approx(10.0)


def test_fft_and_direct_methods_agree_on_dft_bins():
    capture = fixtures.random_capture(seed=4)
    n = 512
    freqs = np.arange(20, 60) / (n * capture.delta_t)                 # bins of a 512-point DFT
    assert dft_length(freqs, capture.delta_t, capture.n_bins) == n
    by_fft = FFTTransform({"frequencies": freqs.tolist(), "method": "fft"}).transform(capture)
    direct = FFTTransform({"frequencies": freqs.tolist(), "method": "direct"}).transform(capture)
    assert by_fft.metadata["method"] == "fft" and direct.metadata["method"] == "direct"
    expected = reference.naive_capture_field(capture, freqs)
    for field in (by_fft, direct):
        assert np.max(np.abs(field.values - expected)) <= 1e-10 * np.max(np.abs(expected))


def test_fft_method_on_frequencies_off_the_bins_is_a_config_error():
    with pytest.raises(ConfigError, match="method"):
        FFTTransform({"frequencies": [1.2345], "method": "fft"}).transform(
            fixtures.point_capture())


def test_streaming_in_small_chunks_changes_nothing():
    rng = np.random.default_rng(0)
    H = rng.random((700, 37))
    freqs = np.linspace(1.0, 40.0, 23)
    full, _ = temporal_dft(H, 0.3, 0.01, freqs, "direct", max_chunk_bytes=1 << 30)
    tiny, _ = temporal_dft(H, 0.3, 0.01, freqs, "direct", max_chunk_bytes=1)
    expected = reference.naive_dft(H, 0.3, 0.01, freqs)
    np.testing.assert_allclose(full, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(tiny, full, rtol=0, atol=1e-13 * np.abs(full).max())


@pytest.mark.parametrize("method, freqs", [
    ("direct", np.linspace(2.0, 16.0, 400)),
    ("fft", np.arange(100, 500) / (2048 * 0.003)),
])
def test_memory_stays_near_twice_the_output(method, freqs):
    rng = np.random.default_rng(0)
    H = rng.random((2048, 2048), dtype=np.float32)               # 16 MiB of float32
    output = 16 * freqs.size * H.shape[1]                        # 12.5 MiB complex128
    tracemalloc.start()
    try:
        temporal_dft(H, 0.0, 0.003, freqs, method)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= 2.3 * output + (9 << 20), f"peak {peak / 2**20:.1f} MiB"


def test_device_legs_are_removed_by_default_and_kept_on_request():
    capture = fixtures.point_capture(device_legs=True)
    removed = FFTTransform({"n_frequencies": 8}).transform(capture)
    kept = FFTTransform({"n_frequencies": 8, "remove_device_legs": False}).transform(capture)
    assert not removed.geometry.t_accounts_first_and_last_bounces
    assert removed.metadata["device_legs_removed"] is True
    assert kept.geometry.t_accounts_first_and_last_bounces
    assert kept.metadata["device_legs_removed"] is False
    legs = reference.device_legs(capture.geometry, capture.sensor_grid_xyz.transpose(1, 0, 2))
    f = removed.frequencies[:, None, None]
    np.testing.assert_allclose(removed.values, kept.values * np.exp(2j * np.pi * f * legs),
                               rtol=0, atol=1e-12 * np.abs(kept.values).max())


def test_sensor_list_capture_becomes_a_one_row_field():
    grid = fixtures.point_capture()
    points = grid.sensor_grid_xyz.reshape(-1, 3)
    H = grid.H.reshape(grid.n_bins, -1)
    capture = Capture(H=H, H_format=HFormat.T_Si, sensor_grid_xyz=points,
                      sensor_grid_format=GridFormat.N_3, laser_grid_xyz=grid.laser_grid_xyz,
                      laser_grid_format=grid.laser_grid_format, delta_t=grid.delta_t)
    field = FFTTransform({"n_frequencies": 6}).transform(capture)
    assert field.values.shape == (6, 1, points.shape[0])
    np.testing.assert_array_equal(field.wall_xyz[0], points)
    expected = reference.naive_dft(H, 0.0, grid.delta_t, field.frequencies)
    np.testing.assert_allclose(field.values[:, 0], expected, rtol=0,
                               atol=1e-10 * np.abs(expected).max())
    assert grid_spacing(points) == pytest.approx(SPACING)


def test_frequency_domain_capture_is_refused():
    capture = fixtures.point_capture()
    spectral = capture.replace(H=capture.H[:10].astype(np.complex64), H_format=HFormat.F_Sx_Sy)
    for transform in (FFTTransform(), WaveletTransform()):
        with pytest.raises(DataError, match="time-domain"):
            transform.transform(spectral)


# ------------------------------------------------------------------ wavelet
def test_wavelet_defaults_follow_liu():
    capture = fixtures.point_capture()
    field = WaveletTransform().transform(capture)
    wavelength = 4 * SPACING
    sigma = 5 * wavelength / 6
    info = field.metadata["wavelet"]
    assert info["wavelength"] == pytest.approx(wavelength)
    assert info["sigma"] == pytest.approx(sigma)
    df = np.diff(field.frequencies)
    # the step resolves the capture window plus the pulse: no wrap-around in time
    assert df.max() <= 1 / (capture.n_bins * capture.delta_t + 6 * sigma) + 1e-12
    n = round(1 / (df[0] * capture.delta_t))
    assert np.allclose(field.frequencies * n * capture.delta_t,
                       np.round(field.frequencies * n * capture.delta_t), atol=1e-9)
    sigma_f = 1 / (2 * np.pi * sigma)
    assert np.all(np.abs(field.frequencies - 1 / wavelength) <= 3 * sigma_f + 1e-12)


def test_wavelet_weights_rebuild_the_pulse_in_time():
    field = WaveletTransform().transform(fixtures.point_capture())
    info = field.metadata["wavelet"]
    sigma, wavelength = info["sigma"], info["wavelength"]
    t = np.linspace(-3 * sigma, 3 * sigma, 61)
    rebuilt = np.exp(2j * np.pi * t[:, None] * field.frequencies[None]) @ field.weights
    pulse = np.exp(-t**2 / (2 * sigma**2)) * np.exp(2j * np.pi * t / wavelength)
    assert np.max(np.abs(rebuilt - pulse)) < 0.02                       # truncation at ±3 sigma_f


def test_wavelet_filtered_signal_peaks_at_the_path_length():
    """sum_f w_f P_f exp(2 pi i f t) is H convolved with K: it peaks at each sensor's path."""
    target = np.array((0.1, -0.05, 0.5))
    capture = fixtures.point_capture(target=tuple(target), bins=400, bin_width=0.005)
    field = WaveletTransform({"wavelength_factor": 1.5}).transform(capture)
    t = np.arange(0.5, 1.6, 0.0025)
    signal = np.einsum("tf,f,fyx->tyx", np.exp(2j * np.pi * t[:, None] * field.frequencies),
                       field.weights, field.values)
    peak_t = t[np.argmax(np.abs(signal), axis=0)]
    wall = field.wall_xyz
    path = np.linalg.norm(target) + np.linalg.norm(wall - target, axis=-1)
    assert np.max(np.abs(peak_t - path)) <= 0.005                        # a bin (plus grid step)


def test_wavelet_explicit_wavelength_and_step():
    capture = fixtures.point_capture()
    field = WaveletTransform({"wavelength": 0.5, "n_cycles": 4, "frequency_step": 0.05}
                             ).transform(capture)
    np.testing.assert_allclose(np.diff(field.frequencies), 0.05)
    assert field.metadata["wavelet"]["wavelength"] == 0.5
    assert field.metadata["wavelet"]["sigma"] == pytest.approx(4 * 0.5 / 6)
    assert field.metadata["method"] == "direct"


def test_wavelet_finer_than_the_grid_records_its_aliasing():
    field = WaveletTransform({"wavelength_factor": 1.5}).transform(fixtures.point_capture())
    assert field.band.aliases and "alias" in band_warning(field)


def test_wavelet_too_few_cycles_drops_non_positive_bins(caplog):
    with caplog.at_level(logging.WARNING):
        field = WaveletTransform({"n_cycles": 1.0}).transform(fixtures.point_capture())
    assert field.frequencies.min() > 0
    assert any("f <= 0" in r.getMessage() for r in caplog.records)


def test_wavelet_beyond_nyquist_is_an_error():
    capture = fixtures.point_capture(bins=40, bin_width=0.1)             # Nyquist 5
    with pytest.raises(ConfigError, match="Nyquist"):
        WaveletTransform({"wavelength": 0.21}).transform(capture)


@pytest.mark.parametrize("options", [{"n_cycles": 0.0}, {"wavelength": -1.0},
                                     {"sigma_range": 0.0}, {"frequency_step": 0.0}])
def test_wavelet_bad_options(options):
    with pytest.raises(ConfigError):
        WaveletTransform(options)

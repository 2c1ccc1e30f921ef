"""The automatic frequency band and depth planes follow the capture's geometry.

A confocal scan doubles the path (laser and sensor legs move together), so the wall
field oscillates twice as fast and the highest non-aliasing frequency is 1/(4Δ),
half of the single-spot 1/(2Δ); depth planes are a quarter of the shortest
wavelength of the wave in the volume apart, 1/(4 m f_max).
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from nlosfw.capture.enums import CaptureKind
from nlosfw.image.depths import automatic_depths, depth_step
from nlosfw.image.fft import FFTImager
from nlosfw.plugins import load_plugins
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.frequencies import spatial_limit
from nlosfw.transform.wavelet import WaveletTransform

RES = 16                       # 16 x 16 sensors on a 1 m wall: Δ = 1/16 m
SPACING = 1.0 / RES


def point_capture(position: tuple[float, float, float], confocal: bool = True):
    config = {"name": "point", "wall": {"size": [1.0, 1.0], "resolution": [RES, RES]},
              "capture": {"type": "confocal" if confocal else "single_spot"},
              "time": {"bins": 512, "bin_width": 0.004, "start": 0.0},
              "geometry": [{"type": "point", "position": list(position), "albedo": 0.01}]}
    return AnalyticSimulator().simulate(scene_from_config(config))


def test_confocal_limit_is_exactly_half_the_single_spot_one():
    for spacing in (0.01, SPACING, 0.031):
        single = spatial_limit(spacing, CaptureKind.SINGLE_SPOT)
        assert single == pytest.approx(1 / (2 * spacing), rel=1e-15)
        assert spatial_limit(spacing, CaptureKind.CONFOCAL) == pytest.approx(single / 2,
                                                                           rel=1e-15)


def test_automatic_band_ends_at_the_limit_of_each_geometry():
    confocal = FFTTransform().transform(point_capture((0.1, -0.05, 0.5)))
    single = FFTTransform().transform(point_capture((0.1, -0.05, 0.5), confocal=False))
    assert confocal.frequencies[-1] == pytest.approx(1 / (4 * SPACING))      # 4 cycles/m
    assert confocal.frequencies[0] == pytest.approx(1 / (16 * SPACING))
    assert single.frequencies[-1] == pytest.approx(1 / (2 * SPACING))        # 8 cycles/m
    assert confocal.band.to_dict() == {"grid_spacing": pytest.approx(SPACING),
                                       "spatial_limit": pytest.approx(4.0),
                                       "option": "transform.f_min", "aliases": False}
    assert "band" not in confocal.metadata


def test_automatic_wavelet_is_twice_as_long_for_confocal():
    capture = point_capture((0.1, -0.05, 0.5))
    field = WaveletTransform().transform(capture)
    assert field.metadata["wavelet"]["wavelength"] == pytest.approx(8 * SPACING)
    assert field.frequencies.max() <= spatial_limit(SPACING, CaptureKind.CONFOCAL)
    assert not field.band.aliases


@pytest.mark.parametrize("position", [(0.0, -0.05, 0.15), (0.3, -0.05, 0.2)])
def test_automatic_band_images_a_confocal_point_without_aliasing_ghosts(position):
    """Near the wall most wall samples see the point at a steep angle, where the confocal
    field of the single-spot band (f up to 1/(2Δ)) is undersampled: it images a ghost
    0.3 m away at a few percent of the peak; the automatic band does not."""
    capture = point_capture(position)
    depths = np.arange(0.06, 0.8, 0.02)
    ghosts = {}
    for label, options in (("auto", {}), ("single_spot_band", {"f_max": 1 / (2 * SPACING)})):
        field = FFTTransform({"n_frequencies": 64, **options}).transform(capture)
        voxels = fixtures.aligned_voxels(field.wall_xyz, depths)
        volume = FFTImager().reconstruct(field, voxels).intensity
        peak = voxels[np.unravel_index(np.argmax(volume), volume.shape)]
        assert np.hypot(peak[0] - position[0], peak[1] - position[1]) <= 1.5 * SPACING
        assert abs(peak[2] - position[2]) <= 0.06
        far = np.linalg.norm(voxels - np.asarray(position), axis=-1) > 0.25
        ghosts[label] = float(volume[far].max() / volume.max())
    assert ghosts["auto"] < 0.012, ghosts
    assert ghosts["single_spot_band"] > 0.03, ghosts            # the test can fail


def test_depth_step_is_a_quarter_wavelength_in_the_volume():
    assert depth_step(8.0, CaptureKind.SINGLE_SPOT) == pytest.approx(1 / 32)
    assert depth_step(4.0, CaptureKind.CONFOCAL) == pytest.approx(1 / 32)    # path = 2 z
    # with the automatic band both are half the wall spacing
    for kind in CaptureKind.SINGLE_SPOT, CaptureKind.CONFOCAL:
        assert depth_step(spatial_limit(SPACING, kind), kind) == pytest.approx(SPACING / 2)
    depths = automatic_depths((0.5, 1.0), 4.0, CaptureKind.CONFOCAL)
    assert depths[0] == 0.5 and depths[-1] == 1.0
    assert np.all(np.diff(depths) <= 1 / 32 + 1e-12) and depths.size == 17


def run_tiny(tmp_path, overrides, name):
    from tests.pipeline.test_pipeline import compose, pipeline

    host = load_plugins()
    config = compose(["scene=tiny", "model=interp", "figures.enabled=false",
                      "transform.n_frequencies=21", "scene.capture.type=confocal",
                      "stop_after=reconstruct", *overrides], host)
    pipeline(tmp_path / name, config, host).run()
    return json.loads((tmp_path / name / "metrics.json").read_text())


def test_aliasing_band_warns_once_per_run_even_from_the_cache(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    # tiny: 16 x 16 sensors on 1 m, confocal limit 4 cycles/m; a noisy scene transforms
    # two captures (noisy and clean): still one warning
    overrides = ["transform.f_max=6.0", "scene.noise.model=poisson", "scene.noise.photons=1e6"]
    for name in ("first", "cached"):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            metrics = run_tiny(tmp_path, overrides, name)
        warnings = [r.getMessage() for r in caplog.records
                    if r.levelno == logging.WARNING and "alias" in r.getMessage()]
        assert len(warnings) == 1, (name, warnings)
        assert "1/(4Δ) = 4 cycles/m" in warnings[0] and "transform.f_max" in warnings[0]
    assert metrics["transform"]["cache_hit"]
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        run_tiny(tmp_path, [], "automatic")
    assert not [r for r in caplog.records if "alias" in r.getMessage()]


def test_pipeline_chooses_depths_from_the_band_and_records_them(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    metrics = run_tiny(tmp_path, [], "auto")["reconstruction"]
    # confocal, f_max = 4 cycles/m: planes <= 1/32 m apart over the ground truth at 0.6 m
    # (+- 0.15 m margin)
    depths = np.asarray(metrics["depths"])
    assert depths[0] == pytest.approx(0.45) and depths[-1] == pytest.approx(0.75)
    assert metrics["depth_planes"] == depths.size == 11
    assert metrics["depth_spacing"] == pytest.approx(0.03)
    fixed = run_tiny(tmp_path, ["reconstruction.n_depths=4"], "fixed")["reconstruction"]
    assert fixed["depth_planes"] == 4 and fixed["depth_spacing"] == pytest.approx(0.1)

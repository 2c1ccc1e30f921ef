"""The ``lct`` imager against a reference light-cone transform written from the paper's
equations (tests/image/lct_reference.py, independent of nlosfw/image/lct.py): the same image to
1e-3 relative L2 on a small simulated confocal capture and on the shared Stanford captures."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw import load_capture
from nlosfw.capture.preprocess import TimeCrop
from nlosfw.image.lct import LCTImager, LCTImagerConfig
from nlosfw.image.transient import Falloff, canonical_wall, full_band_frequencies
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.fft import FFTTransform, FFTTransformConfig
from tests.image.lct_reference import Settings, reference_lct
from tests.real_data import LCT_CAPTURES, real_capture


def canonical_histograms(capture) -> tuple[np.ndarray, tuple[float, float]]:
    """The capture's histograms (T, Y, X) on the canonical wall grid (y and x increasing)
    and the grid's spacing, found from the sensor positions alone."""
    xyz = capture.sensor_points                                   # (S, 3), H's flat order
    xs, ys = np.unique(np.round(xyz[:, 0], 9)), np.unique(np.round(xyz[:, 1], 9))
    cols = np.searchsorted(xs, np.round(xyz[:, 0], 9))
    rows = np.searchsorted(ys, np.round(xyz[:, 1], 9))
    out = np.zeros((capture.n_bins, ys.size, xs.size))
    out[:, rows, cols] = capture.H.reshape(capture.n_bins, -1)
    return out, (float(ys[1] - ys[0]), float(xs[1] - xs[0]))


def compare(capture, depths, falloff: str, snr: float, max_bins: int) -> float:
    """Relative L2 between the imager's intensity and the reference's on the same planes."""
    band = full_band_frequencies(capture.n_bins, capture.delta_t)
    field = FFTTransform(FFTTransformConfig(frequencies=tuple(band))).transform(capture)
    grid = canonical_wall(field)
    voxels = fixtures.aligned_voxels(field.wall_xyz, depths)
    imager = LCTImager(LCTImagerConfig(falloff=Falloff(falloff), snr=snr, max_bins=max_bins))
    recon = imager.reconstruct(field, voxels)
    # the imager's voxels in the canonical grid's (row, column) order
    (y0, x0), (dy, dx) = grid.origin, grid.spacing
    rows = np.rint((voxels[..., 1] - y0) / dy).astype(int)
    cols = np.rint((voxels[..., 0] - x0) / dx).astype(int)
    histograms, spacing = canonical_histograms(capture)
    assert spacing == pytest.approx((dy, dx), rel=1e-9)
    settings = Settings(falloff_power=4 if falloff == "diffuse" else 2, snr=snr,
                        max_bins=max_bins)
    ref = reference_lct(histograms, capture.delta_t, spacing, depths, settings)
    ref_at_voxels = ref[np.arange(len(depths))[:, None, None], rows, cols]
    assert np.linalg.norm(ref) > 0
    error = float(np.linalg.norm(recon.intensity - ref_at_voxels) / np.linalg.norm(ref))
    print(f"lct vs reference: relative L2 {error:.2e}")
    return error


@pytest.mark.parametrize(("falloff", "snr"), [("diffuse", 0.08), ("retroreflective", 0.8)])
def test_lct_imager_matches_the_reference_on_a_simulated_capture(falloff, snr):
    config = layouts.lct_scene(resolution=10, bins=400)
    config["wall"]["size"] = [0.5, 0.5]
    config["geometry"] = [{"type": "rectangle", "position": [0.05, -0.03, 0.2],
                           "size": [0.12, 0.06]}]
    capture = AnalyticSimulator().simulate(scene_from_config(config))
    depths = np.linspace(0.12, 0.28, 9)
    assert compare(capture, depths, falloff, snr, max_bins=256) <= 1e-3


@pytest.mark.parametrize("name", LCT_CAPTURES)
def test_lct_imager_matches_the_reference_on_the_shared_captures(name):
    path = real_capture(name)
    # small and fast: 16 x 16 (4 x 4 blocks summed), the first 1024 bins, the format's gate
    capture = load_capture(path, time_crop=TimeCrop(bins=(0, 1024)), bin=4)
    depths = np.linspace(0.3, 0.55, 6)
    assert compare(capture, depths, "diffuse", 0.08, max_bins=256) <= 1e-3


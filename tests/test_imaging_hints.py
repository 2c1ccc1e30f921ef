"""Imaging hints (issue 21): the authors' per-capture settings travel from an LCT file to the
transient imagers, which use them unless their own options are set."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw import load_capture
from nlosfw.capture.hints import HINTS_KEY, ImagingHints, capture_hints
from nlosfw.image.lct import LCTImager, LCTImagerConfig
from nlosfw.image.transient import Falloff
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.fft import FFTTransform


@pytest.fixture(scope="module")
def capture():
    config = layouts.lct_scene(resolution=8, bins=1700)
    return AnalyticSimulator().simulate(scene_from_config(config))


@pytest.mark.parametrize(("stem", "falloff", "snr", "near"), [
    ("data_diffuse_s", "diffuse", 0.08, 100), ("data_dot_chart_40cm", "retroreflective", 0.8, 350),
    ("data_resolution_chart_40cm", "retroreflective", 0.8, 350)])
def test_known_lct_files_carry_the_authors_settings(tmp_path, capture, stem, falloff, snr, near):
    path = layouts.write_lct(tmp_path / f"{stem}.mat", capture)
    hints = capture_hints(load_capture(path))
    assert (hints.falloff, hints.snr) == (falloff, snr)
    # their window: z_offset bins of depth (half a 4 ps bin of path each), 2 width deep,
    # within the histogram's reach
    dz = capture.delta_t / 2
    far = min(near * dz + 1.0, capture.n_bins * dz)
    assert hints.depth_window == pytest.approx((near * dz, far), rel=1e-9)


def test_other_files_carry_no_hints(tmp_path, capture):
    path = layouts.write_lct(tmp_path / "scan.mat", capture)
    assert capture_hints(load_capture(path)) == ImagingHints()


def test_imagers_use_the_hints_unless_set_explicitly(tmp_path, capture):
    path = layouts.write_lct(tmp_path / "data_dot_chart_40cm.mat", capture)
    field = FFTTransform().transform(load_capture(path))
    assert field.metadata[HINTS_KEY]["snr"] == 0.8
    voxels = fixtures.aligned_voxels(field.wall_xyz, np.linspace(0.5, 0.7, 5))
    hinted = LCTImager().reconstruct(field, voxels)
    explicit = LCTImager(LCTImagerConfig(falloff=Falloff.retroreflective, snr=0.8)
                         ).reconstruct(field, voxels)
    overridden = LCTImager(LCTImagerConfig(falloff=Falloff.diffuse, snr=0.08)
                           ).reconstruct(field, voxels)
    assert (hinted.metadata["falloff"], hinted.metadata["snr"]) == ("retroreflective", 0.8)
    np.testing.assert_array_equal(hinted.intensity, explicit.intensity)
    assert (overridden.metadata["falloff"], overridden.metadata["snr"]) == ("diffuse", 0.08)
    difference = np.linalg.norm(overridden.intensity - hinted.intensity)
    assert difference > 0.01 * np.linalg.norm(hinted.intensity)
    # no hints at all: the documented defaults
    plain = field.replace(metadata={})
    default = LCTImager().reconstruct(plain, voxels)
    assert (default.metadata["falloff"], default.metadata["snr"]) == ("diffuse", 0.08)


def test_bad_hints_in_a_file_are_ignored():
    hints = ImagingHints.from_mapping({"falloff": "shiny", "snr": -1, "depth_window": [2, 1]})
    assert hints == ImagingHints()

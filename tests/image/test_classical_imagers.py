"""The classical confocal imagers lct, fk and fbp.

They pass the conformance kit (tests/conformance); here they image a simulated
confocal capture of a letter in the layout of the Stanford LCT captures (a square
scan 0.7 m wide, 4 ps bins, no direct reflection in the window) and agree with the
phasor-field imagers and with the ground truth on where the letter is.
"""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.common.errors import DataError
from nlosfw.image.depths import automatic_depths, depth_span
from nlosfw.image.fk import FKImager
from nlosfw.image.lct import FBPImager, LCTImager
from nlosfw.image.transient import full_band_frequencies
from nlosfw.plugins import load_plugins
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.builtin_scenes import builtin_scene
from nlosfw.testing import fixtures
from nlosfw.transform.fft import FFTTransform

BIN = 0.0012                 # 4 ps of light travel
LETTER_DEPTH = 0.9


@pytest.fixture(scope="module")
def letter():
    """letter_t, 32 x 32 confocal scan of a 0.7 m square, bins from 1.6 m of path."""
    scene = builtin_scene("letter_t", wall={"size": [0.7, 0.7], "resolution": [32, 32]},
                          capture={"type": "confocal"},
                          time={"bins": 1083, "bin_width": BIN, "start": 1.6})
    capture = AnalyticSimulator().simulate(scene)
    field = FFTTransform().transform(capture)
    depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                              field.geometry.kind)
    truth = np.asarray(capture.scene_info["ground_truth"]["depth"]).T > 0     # (Y, X)
    return capture, field, fixtures.aligned_voxels(field.wall_xyz, depths), truth


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def summary(recon):
    image = recon.max_intensity_image()
    mask = image > 0.3 * image.max()
    return mask, recon.depth_map()


def test_classical_and_phasor_imagers_agree_on_the_letter(letter):
    _, field, voxels, truth = letter
    step = float(voxels[1, 0, 0, 2] - voxels[0, 0, 0, 2])
    host = load_plugins()
    masks, depth_maps = {}, {}
    for name in ("fft", "lct", "fk", "fbp"):
        recon = host.registry.create("imager", name).reconstruct(field, voxels)
        masks[name], depth_maps[name] = summary(recon)
    for name, mask in masks.items():
        depth = depth_maps[name][mask]
        near = np.abs(depth - LETTER_DEPTH) <= 2 * step
        assert iou(mask, truth) >= 0.65, (name, iou(mask, truth))
        assert iou(mask, masks["fft"]) >= 0.8, (name, iou(mask, masks["fft"]))
        assert near.mean() >= 0.9, (name, near.mean())
        assert abs(np.median(depth) - LETTER_DEPTH) <= step, (name, np.median(depth))
    # rsd is the same image as fft (a few planes around the letter: it is slow)
    around = voxels[np.abs(voxels[:, 0, 0, 2] - LETTER_DEPTH) <= 1.5 * step]
    slow = host.registry.create("imager", "rsd").reconstruct(field, around)
    fast = host.registry.create("imager", "fft").reconstruct(field, around)
    assert iou(summary(slow)[0], summary(fast)[0]) >= 0.98


def test_full_band_transient_gives_the_letter_too(letter):
    """With every DFT bin of the capture the imagers see the whole transient (the
    published setting): the letter is where it is with the automatic band."""
    capture, _, voxels, truth = letter
    every_bin = full_band_frequencies(capture.n_bins, capture.delta_t)
    band = every_bin[every_bin <= 1 / (4 * 0.7 / 32)]            # up to the confocal limit
    field = FFTTransform({"frequencies": tuple(band)}).transform(capture)
    for imager in (LCTImager(), FKImager()):
        mask, depth = summary(imager.reconstruct(field, voxels))
        assert iou(mask, truth) >= 0.6
        assert abs(np.median(depth[mask]) - LETTER_DEPTH) <= 0.02


@pytest.mark.parametrize("imager", [LCTImager, FKImager, FBPImager])
def test_single_spot_fields_and_off_grid_voxels_are_one_line_errors(imager):
    field = fixtures.point_field((0.1, 0.0, 0.6), confocal=False)
    voxels = fixtures.aligned_voxels(field.wall_xyz, [0.5, 0.6])
    with pytest.raises(DataError, match="confocal fields only") as err:
        imager().reconstruct(field, voxels)
    assert "\n" not in str(err.value)
    confocal = fixtures.point_field((0.1, 0.0, 0.6), confocal=True)
    shifted = voxels.copy()
    shifted[..., 0] += 0.01
    with pytest.raises(DataError, match="not one of its samples"):
        imager().reconstruct(confocal, shifted)
    with pytest.raises(DataError, match="point list"):
        imager().reconstruct(confocal, voxels.reshape(-1, 3))

"""lct, fk, fbp and fft on the shared Stanford LCT captures against the authors' LCT:
front view NCC >= 0.8 and brightest depth within 3 cm.

The authors' LCT is tests/image/lct_reference.py's ``authors_lct`` (their MATLAB procedure and
per-scene settings); both sides see the scan binned 2 x 2 (32 x 32, as some of their
published scenes are) and 8 ps bins on their side, to stay small. nlosfw's imagers run with
their defaults on a copy of the capture under a neutral name (``capture_a.mat``), as
``nlosfw.load_capture`` reads it: their falloff and Wiener SNR come from the data, never
from the file's name. At the automatic depths: lct, fk and fbp over the measured-capture
band, fft over the default transform's band.
``studies/classical_imagers_measured/run.py`` measures the same at full resolution."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from nlosfw import load_capture
from nlosfw.image.depths import automatic_depths, depth_span
from nlosfw.image.measured import measured_field
from nlosfw.image.transient import canonical_wall
from nlosfw.plugins import load_plugins
from nlosfw.transform.fft import FFTTransform
from tests.image.lct_reference import AUTHORS_SCENES, authors_lct
from tests.real_data import LCT_CAPTURES, real_capture

_AUTHORS: dict[str, tuple[np.ndarray, float]] = {}


def authors_view(name: str) -> tuple[np.ndarray, float]:
    """Their front view (canonical grid, 32 x 32) and brightest depth, computed once."""
    if name not in _AUTHORS:
        data = scipy.io.loadmat(real_capture(name))
        rect = data["rect_data"].astype(np.float64)
        n = rect.shape[0] // 2
        rect = rect.reshape(n, 2, n, 2, -1).sum(axis=(1, 3))
        settings = dataclasses.replace(AUTHORS_SCENES[name], downsample=1)
        vol, z = authors_lct(rect, float(np.squeeze(data["width"])), 4e-12, settings)
        _AUTHORS[name] = (vol.max(axis=0),
                          float(z[np.unravel_index(int(np.argmax(vol)), vol.shape)[0]]))
    return _AUTHORS[name]


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def neutral_copy(name: str, folder: Path) -> Path:
    """The shared capture ``name`` copied to ``folder/capture_a.mat`` (a name that says
    nothing about the scene)."""
    return Path(shutil.copyfile(real_capture(name), folder / "capture_a.mat"))


def image(path: Path, imager: str):
    """(field, depths, reconstruction) of ``imager`` at the automatic depths, the capture
    binned 2 x 2: the transient imagers over the measured-capture band, fft over its
    default band."""
    capture = load_capture(path, bin=2)
    field = FFTTransform().transform(capture) if imager == "fft" else measured_field(capture)
    depths = automatic_depths(depth_span(capture), float(field.frequencies.max()),
                              field.geometry.kind)
    voxels = np.repeat(field.wall_xyz[None], depths.size, axis=0)
    voxels[..., 2] = depths[:, None, None]
    return field, depths, load_plugins().registry.create("imager", imager).reconstruct(
        field, voxels)


@pytest.mark.parametrize(("name", "imager"), [
    (name, imager) for name in LCT_CAPTURES for imager in ("lct", "fk", "fft", "fbp")])
def test_imager_finds_the_object_as_the_authors_lct_does(tmp_path, name, imager):
    reference, their_depth = authors_view(name)
    field, depths, recon = image(neutral_copy(name, tmp_path), imager)
    amplitude = np.sqrt(recon.intensity)
    grid = canonical_wall(field)
    rows = np.rint((field.wall_xyz[..., 1] - grid.origin[0]) / grid.spacing[0]).astype(int)
    cols = np.rint((field.wall_xyz[..., 0] - grid.origin[1]) / grid.spacing[1]).astype(int)
    front = np.zeros(grid.shape)
    front[rows, cols] = amplitude.max(axis=0)
    brightest = float(depths[np.unravel_index(int(np.argmax(amplitude)), amplitude.shape)[0]])
    score = ncc(front, reference)
    print(f"{name} {imager}: NCC {score:.3f}, brightest depth {brightest:.3f} m "
          f"(authors {their_depth:.3f} m)")
    assert score >= 0.8
    assert abs(brightest - their_depth) <= 0.03


@pytest.mark.parametrize("name", LCT_CAPTURES)
def test_a_capture_images_the_same_whatever_its_file_is_called(tmp_path, name):
    """The settings lct takes from a capture (falloff, Wiener SNR) depend on its data alone:
    the file under its published name and under a neutral one give the same image."""
    published = shutil.copyfile(real_capture(name), tmp_path / f"{name}.mat")
    renamed = neutral_copy(name, tmp_path)
    _, _, first = image(Path(published), "lct")
    _, _, second = image(renamed, "lct")
    assert (first.metadata["falloff"], first.metadata["snr"]) == (
        second.metadata["falloff"], second.metadata["snr"])
    np.testing.assert_array_equal(first.intensity, second.intensity)

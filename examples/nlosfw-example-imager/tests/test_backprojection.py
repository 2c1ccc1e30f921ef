"""The example imager against the core's: the same image as the direct RSD imager, and a
point scatterer focused where it is."""

import subprocess
import sys

import numpy as np

from nlosfw import depth_span, reconstruct, simulate_scene, transform_capture
from nlosfw.image import volume_voxels
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures


def test_same_image_as_the_rsd_imager_on_a_simulated_capture():
    capture = simulate_scene("tiny")
    field = transform_capture(capture, "fft", n_frequencies=15)
    depths = np.linspace(*depth_span(capture), 5)
    ours = reconstruct(field, depths, "example_backprojection", block=50)
    reference = reconstruct(field, depths, "rsd")
    np.testing.assert_allclose(ours.intensity, reference.intensity, rtol=1e-9,
                               atol=1e-12 * reference.intensity.max())


def test_point_scatterer_is_brightest_at_its_position():
    target = (0.1, -0.05, 0.5)
    f, w = fixtures.gaussian_band(4.0, 0.75, n=9)
    field = fixtures.point_field(target, shape=(12, 12), spacing=1 / 16, frequencies=f,
                                 weights=w, confocal=True, device_legs=False)
    # 13 x 13 x 3 voxels whose centre voxel (1, 6, 6) is the point
    voxels = volume_voxels([0.4, 0.5, 0.6], (-0.2, 0.4), (-0.35, 0.25), (13, 13))
    np.testing.assert_allclose(voxels[1, 6, 6], target)
    imager = load_plugins().registry.create("imager", "example_backprojection")
    intensity = imager.reconstruct(field, voxels).intensity
    assert np.unravel_index(np.argmax(intensity), intensity.shape) == (1, 6, 6)


def test_the_kit_runs_on_this_package_in_one_command(tmp_path):
    plan = subprocess.run([sys.executable, "-m", "nlosfw.testing", "nlosfw-example-imager",
                           "--plan"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert plan.returncode == 0, plan.stderr
    assert plan.stdout.startswith("imager:example_backprojection from nlosfw-example-imager\n")
    assert "18 to run, 0 skipped" in plan.stdout   # rsd, progress declared: their checks run

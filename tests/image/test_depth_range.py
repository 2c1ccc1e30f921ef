"""The automatic depth range: where the signal rises above the background, not
the last bin with counts; and the same range bounds rsd_prior's depth search."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from nlosfw import load_capture
from nlosfw.capture.signal import signal_bins, signal_depth_range
from nlosfw.evaluation.splits import split_field
from nlosfw.image.depths import depth_span
from nlosfw.model.physics.prior import RSDPriorFieldModel
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from tests.model.physics.test_prior import _field, _point_field
from tests.real_data import LCT_CAPTURES, real_capture

DEPTH = 0.5


@pytest.fixture(scope="module")
def measured_like():
    """A patch 0.5 m from the wall, scanned confocally (16 x 16 over 0.6 m, 4 ps bins, 2000
    bins: 1.2 m deep), as photon counts on a dark-count floor with Poisson noise and the
    direct reflection's tail after a gate, without ground truth (as read from a file)."""
    config = layouts.lct_scene(resolution=16, bins=2000)
    config["wall"]["size"] = [0.6, 0.6]
    config["geometry"] = [{"type": "rectangle", "position": [0.0, 0.0, DEPTH],
                           "size": [0.2, 0.2]}]
    capture = AnalyticSimulator().simulate(scene_from_config(config))
    signal = capture.H / capture.H.max() * 40
    t = np.arange(capture.n_bins)[:, None, None]
    direct = np.where(t >= 600, 30 * np.exp(-(t - 600) / 60.0), 0)
    rng = np.random.default_rng(0)
    counts = rng.poisson(signal + direct + 0.5 * (t >= 600)).astype(np.float32)
    return capture.replace(H=counts, scene_info={}), capture


def test_range_holds_the_object_and_stops_where_its_signal_does(measured_like):
    noisy, clean = measured_like
    near, far = depth_span(noisy)
    assert near <= DEPTH
    # the farthest path of the patch seen from the scan's corners, halved
    corners = np.array([[x, y, 0] for x in (-0.3, 0.3) for y in (-0.3, 0.3)])
    patch = np.array([[x, y, DEPTH] for x in (-0.1, 0.1) for y in (-0.1, 0.1)])
    farthest = np.linalg.norm(corners[:, None] - patch[None], axis=-1).max()
    assert DEPTH + 0.02 <= far <= farthest + 0.02
    assert far < 0.9 * clean.n_bins * clean.delta_t / 2      # not the end of the histogram


def test_signal_bins_of_a_flat_background_and_of_nothing():
    rng = np.random.default_rng(1)
    assert signal_bins(np.zeros(100)) is None
    flat = rng.poisson(50, 1000).astype(float)
    pulse = flat.copy()
    pulse[400:420] += 2000
    first, last = signal_bins(pulse)
    assert 395 <= first <= 405 and 415 <= last <= 425


def test_the_run_range_bounds_rsd_priors_depth_search(caplog):
    wall = fixtures.rect_wall_grid((12, 12), 1 / 12)
    freqs = np.linspace(3.0, 6.0, 21)
    meta = {"t_start": 0.0, "n_bins": 300, "delta_t": 0.01}
    full = _field(_point_field((0.1, -0.05, 0.6), wall, freqs, False), wall, freqs, False,
                  meta).replace(depth_range=(0.5, 0.7))
    train = split_field(full, spatial_step=2).train_field
    assert train.depth_range == (0.5, 0.7)
    model = RSDPriorFieldModel({"iterations": 5, "depth": {"iterations": 10}, "workers": 1})
    with caplog.at_level(logging.INFO, logger="nlosfw.model.physics.lattice"):
        model.fit(train)
    depths = model.lattice.depths
    margin = model.config.depth.margin + 1 / (4 * 4.5)
    assert depths.min() >= 0.5 - margin and depths.max() <= 0.7 + margin
    coarse = [r.getMessage() for r in caplog.records if "coarse fit" in r.getMessage()]
    assert len(coarse) == 1 and "[" not in coarse[0] and len(coarse[0]) < 160


@pytest.mark.parametrize("name", LCT_CAPTURES)
def test_shared_captures_range_holds_the_object_and_not_the_late_background(name):
    capture = load_capture(real_capture(name))
    near, far = depth_span(capture)
    assert signal_depth_range(capture) == (near, far)
    # the object: 40 cm (charts), about 0.5 m (the S: the authors' brightest plane)
    depth = 0.5 if name == "data_diffuse_s" else 0.4
    assert near < depth - 0.05 and depth + 0.1 < far < 0.85


# ------------------------------------------------------------------ one rule, decided once
@pytest.mark.parametrize(("overrides", "expected"), [
    (["reconstruction.depths=[0.5,0.7,0.55]", "reconstruction.depth_range=[0.2,1.0]"],
     (0.5, 0.7)),
    (["reconstruction.depth_range=[0.2,1.0]"], (0.2, 1.0)),
    ([], None),
])
def test_a_model_searches_the_depths_the_run_images(overrides, expected, tmp_path, monkeypatch):
    """The range a field model's own depth search is bounded by is the run's one range:
    the near and far of reconstruction.depths when planes are given (they used to be
    ignored there), else reconstruction.depth_range, else the capture's automatic range;
    the reconstructions' planes follow the same rule."""
    from nlosfw.model.interp import InterpFieldModel
    from nlosfw.plugins import load_plugins
    from tests.pipeline.test_pipeline import compose, pipeline

    seen = []
    fit = InterpFieldModel.fit

    def recording(self, field, *args, **kwargs):
        seen.append(field.depth_range)
        return fit(self, field, *args, **kwargs)

    monkeypatch.setattr(InterpFieldModel, "fit", recording)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    host = load_plugins()
    config = compose(["scene=tiny", "model=interp", "figures.enabled=false",
                      "transform.n_frequencies=11", "reconstruction.n_depths=3",
                      "reconstruction.single_frequency_images=0", *overrides], host)
    run = pipeline(tmp_path / "run", config, host)
    run.run()
    results = run.stage_results
    automatic = depth_span(results.capture.capture)
    assert seen == [expected or automatic]
    planes = np.unique(results.reconstructions.voxels[..., 2])
    near, far = expected or automatic
    if overrides and "depths" in overrides[0]:
        np.testing.assert_allclose(planes, [0.5, 0.55, 0.7])
    else:
        np.testing.assert_allclose([planes.min(), planes.max()], [near, far])


def test_the_plan_counts_the_planes_it_will_image_without_making_them(measured_like):
    """The memory estimate sizes the voxels by the planes the run will image, known once a
    capture file is read: as many as the rule makes, whichever option decides them."""
    from nlosfw.capture.enums import CaptureKind
    from nlosfw.pipeline.depth_plan import DepthPlan
    from nlosfw.pipeline.settings import ReconstructionSettings
    from nlosfw.transform.fft import FFTTransform

    capture = measured_like[0]
    field = FFTTransform({"n_frequencies": 5}).transform(capture)
    for settings in (ReconstructionSettings(), ReconstructionSettings(n_depths=7),
                     ReconstructionSettings(depths=(0.4, 0.5)),
                     ReconstructionSettings(depth_range=(0.1, 1.1))):
        rule = DepthPlan.of(settings)
        planes = rule.planes(capture, field)
        assert rule.count(rule.span(capture), float(field.frequencies.max()),
                          CaptureKind.CONFOCAL) == planes.size

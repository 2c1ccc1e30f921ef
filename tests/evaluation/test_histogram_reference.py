"""The reference picture of a run: the measured histograms imaged at their native
bin width beside the scored sources, never scored; and the capture's time profile drawn by
runs stopped before they image.

The capture is a confocal scan of one point scatterer written by the test, with bins
(4 mm of path) fine enough that the histograms' band (to 1/(2 bin) = 125 cycles/m) is twice
the measured-capture band the scored sources are imaged from (0.4-60 cycles/m), so the two
differ, and the point's depth is known: the reference picture must put it there.
"""

from __future__ import annotations

import json
import logging
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import nlosfw
from nlosfw.capture.hdf5 import write_capture
from nlosfw.cli import main
from nlosfw.evaluation.count_splitting import CountSplit
from nlosfw.evaluation.reference import REFERENCE, reference_bytes, reference_capture
from nlosfw.image.depths import depth_span
from nlosfw.image.measured import histogram_field
from nlosfw.image.reconstruction_io import read_reconstruction
from nlosfw.image.transient import MEASURED_BAND
from nlosfw.pipeline.depth_plan import DepthPlan
from nlosfw.pipeline.settings import ReconstructionSettings
from nlosfw.plugins import load_plugins
from tests.real_data import real_capture

POINT = np.array([0.1, -0.05, 0.6])
BIN = 0.004
SCENE = {
    "name": "point_confocal",
    "wall": {"size": [1.0, 1.0], "resolution": [16, 16], "center": [0.0, 0.0]},
    "capture": {"type": "confocal", "laser_position": [-0.5, 0.0, 0.25],
                "sensor_position": [-0.5, 0.0, 0.25], "device_legs": False},
    "time": {"bins": 400, "bin_width": BIN, "start": 0.0},
    "noise": {"model": "none"},
    "geometry": [{"type": "point", "position": POINT.tolist(), "albedo": 0.01}],
}
#: The reference picture's files.
VIEWS = {f"figures/{view}_{REFERENCE}.png" for view in ("front", "depth")}
#: A quick field-model run: no figures, no single-frequency images.
QUICK = ("model=interp", "figures.enabled=false", "reconstruction.single_frequency_images=0",
         "output.keep=[]")


@pytest.fixture(scope="module")
def point_capture(tmp_path_factory):
    capture = nlosfw.simulate_scene(SCENE)
    path = tmp_path_factory.mktemp("capture") / "a&b scan.hdf5"
    write_capture(path, capture)
    return path, capture


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("COLUMNS", "200")
    return tmp_path


def brightest(recon) -> np.ndarray:
    """(x, y, z) of the brightest voxel."""
    volume, voxels = recon.as_volume()
    return voxels[np.unravel_index(int(np.argmax(volume)), volume.shape)]


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels, from the PNG's header."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_image_shows_the_histograms_at_native_bins_beside_the_capture_unscored(
        workdir, point_capture, capsys):
    path, capture = point_capture
    status = main(["image", str(path), "imager=lct", "hydra.run.dir=run", "figures.dpi=30"])
    assert status == 0, capsys.readouterr().err
    run = workdir / "run"
    assert all((run / name).is_file() for name in VIEWS)
    ref = read_reconstruction(run / "reconstructions" / f"{REFERENCE}.hdf5")
    true = read_reconstruction(run / "reconstructions" / "true.hdf5")
    # the reference images every DFT bin of the histograms, the scored capture its band
    ref_f = np.asarray(ref.metadata["frequencies"])
    np.testing.assert_allclose(ref_f, np.arange(1, 201) / (400 * BIN))
    assert max(true.metadata["frequencies"]) <= MEASURED_BAND[1] < ref_f.max() / 2
    np.testing.assert_array_equal(ref.voxels, true.voxels)          # the same planes
    x, y, z = brightest(ref)
    assert abs(z - POINT[2]) <= 2 * BIN / 2 + 1e-9                  # two native depth bins
    assert abs(x - POINT[0]) <= 1 / 16 + 1e-9 and abs(y - POINT[1]) <= 1 / 16 + 1e-9
    # not scored: the metrics know the capture's image only
    metrics = json.loads((run / "metrics.json").read_text())
    assert list(metrics["reconstruction"]["sources"]) == ["true"]
    assert REFERENCE not in (run / "metrics.json").read_text()
    page = (run / "report.html").read_text()
    assert ("<h3>reference: the measured histograms (native bins) · imager lct</h3>"
            in page)
    assert all(f"{Path(name).name}: " in page for name in VIEWS)
    assert "a&amp;b scan.hdf5" in page and "a&b scan" not in page
    assert page.index("front_true.png") < page.index(f"front_{REFERENCE}.png") < page.index(
        "time_profile.png")


def test_a_field_model_run_keeps_the_reference_out_of_its_scores(workdir, point_capture):
    path, _ = point_capture
    out = nlosfw.run([f"capture.path='{path}'", "imager=fk", *QUICK],
                     output_dir=workdir / "run")
    recons = out.results.reconstructions
    assert recons.reference is not None and REFERENCE not in recons.by_source
    assert list(out.metrics.reconstruction.sources) == ["true", "raw", "interp"]
    assert abs(brightest(recons.reference)[2] - POINT[2]) <= 2 * BIN / 2 + 1e-9


@pytest.mark.parametrize(("args", "made", "said"), [
    (["imager=lct", "reconstruction.histogram_reference=false"], False,
     "no reference picture: reconstruction.histogram_reference=false"),
    (["imager=fft"], False, "no reference picture: imager fft images a band"),
    (["imager=fbp", "reconstruction.histogram_reference=true"], True, "reference picture: "
     "the histograms at native bins, 200 frequencies to 125 cycles/m"),
])
def test_when_a_file_run_makes_the_reference(workdir, point_capture, args, made, said):
    path, _ = point_capture
    out = nlosfw.run([f"capture.path='{path}'", *QUICK, *args], output_dir=workdir / "run")
    assert (out.results.reconstructions.reference is not None) is made
    assert said in (out.dir / "run.log").read_text()


def test_a_simulated_capture_has_one_only_when_asked(workdir):
    tiny = ["scene=tiny", "scene.capture.type=confocal", "imager=lct", *QUICK,
            "reconstruction.n_depths=4"]
    auto = nlosfw.run(tiny, output_dir=workdir / "auto")
    assert auto.results.reconstructions.reference is None
    assert "no reference picture: a simulated capture" in (auto.dir / "run.log").read_text()
    asked = nlosfw.run([*tiny, "reconstruction.histogram_reference=true"],
                       output_dir=workdir / "asked")
    assert asked.results.reconstructions.reference is not None


def test_too_large_for_memory_is_skipped_in_one_line_unless_allowed(workdir, point_capture,
                                                                   monkeypatch):
    path, _ = point_capture
    monkeypatch.setattr("nlosfw.evaluation.reference.available_memory", lambda: 1000)
    given = [f"capture.path='{path}'", "imager=lct", *QUICK]
    out = nlosfw.run(given, output_dir=workdir / "small")
    assert out.results.reconstructions.reference is None
    (line,) = [r for r in (out.dir / "run.log").read_text().splitlines()
               if "no reference picture" in r]
    assert "but 1.0 kB are available (limits.allow_large=true makes it anyway)" in line, line
    allowed = nlosfw.run([*given, "limits.allow_large=true"], output_dir=workdir / "large")
    assert allowed.results.reconstructions.reference is not None


def test_asking_for_it_with_a_band_imager_is_one_line_exit_2(workdir, point_capture, capsys):
    path, _ = point_capture
    status = main([f"capture.path='{path}'", "imager=fft",
                   "reconstruction.histogram_reference=true", "hydra.run.dir=run"])
    err = capsys.readouterr().err
    assert status == 2 and err.strip().count("\n") == 0, err
    assert "error: reconstruction.histogram_reference: true images the histograms" in err
    assert not (workdir / "run").exists()


def test_with_count_splitting_the_histograms_are_both_halves_added(point_capture):
    _, capture = point_capture
    a, b = capture.replace(H=capture.H * 0.25), capture.replace(H=capture.H * 0.75)
    halves = CountSplit(a, b, 0, 1.0, 1, 3)
    np.testing.assert_allclose(reference_capture(a, halves).H, capture.H, rtol=1e-6)
    assert reference_capture(a, None) is a


@pytest.mark.parametrize("imager", ["lct", "fk"])
def test_the_memory_estimate_covers_the_imagers_peak(point_capture, imager):
    """Against the peak of the arrays the imager allocates (tracemalloc sees numpy's), the
    estimate is on the generous side, within an order of magnitude."""
    _, capture = point_capture
    field = histogram_field(capture)
    depths = np.linspace(0.4, 0.8, 40)
    voxels = np.repeat(field.wall_xyz[None], depths.size, axis=0)
    voxels[..., 2] = depths[:, None, None]
    plugin = load_plugins().registry.create("imager", imager, {"workers": 1})
    tracemalloc.start()
    try:
        plugin.reconstruct(field, voxels)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    estimate = reference_bytes(capture, depths, plugin.config)
    assert peak <= estimate <= 10 * peak, (peak, estimate)


def test_stop_after_capture_and_transform_draw_the_time_profile(workdir, point_capture):
    path, capture = point_capture
    for stage in ("capture", "transform"):
        run = workdir / stage
        out = nlosfw.run([f"capture.path='{path}'", f"stop_after={stage}", "figures.dpi=40",
                          "output.keep=[]"], output_dir=run)
        assert out.metrics.status == "stopped"
        assert sorted(p.name for p in (run / "figures").iterdir()) == ["time_profile.png"]
        assert png_size(run / "figures" / "time_profile.png") == (320, 152)   # 8 x 3.8 in
        page = (run / "report.html").read_text()
        assert "time_profile.png: the capture&#x27;s histograms summed over the wall" in page
        assert "No figures" not in page


def test_the_run_depth_range_follows_depths_then_depth_range_then_the_signal(point_capture):
    _, capture = point_capture

    def run_depth_range(settings: ReconstructionSettings, capture: object) -> tuple:
        return DepthPlan.of(settings).span(capture)

    assert run_depth_range(ReconstructionSettings(depths=(0.7, 0.5, 0.6)), capture) == (0.5,
                                                                                        0.7)
    assert run_depth_range(ReconstructionSettings(depths=(0.7, 0.5, 0.6),
                                                  depth_range=(0.3, 0.9)), capture) == (0.5,
                                                                                        0.7)
    assert run_depth_range(ReconstructionSettings(depth_range=(0.3, 0.9)), capture) == (0.3,
                                                                                        0.9)
    near, far = run_depth_range(ReconstructionSettings(), capture)
    assert (near, far) == pytest.approx(depth_span(capture))
    assert near < POINT[2] < far          # the point's depth holds signal


def test_the_diffuse_s_reference_is_where_the_authors_find_the_s(workdir):
    """The shared diffuse S, binned to 16 x 16 scan points: the histograms at 4 ps imaged by
    lct put the S's brightest voxel within 3 cm of the authors' LCT (0.504 m,
    studies/classical_imagers_measured/run.py)."""
    path = real_capture("data_diffuse_s")
    out = nlosfw.run([f"capture.path='{path}'", "model=none", "imager=lct", "capture.bin=4",
                      "figures.enabled=false", "output.keep=[]"], output_dir=workdir / "run")
    reference = out.results.reconstructions.reference
    assert reference is not None
    assert len(reference.metadata["frequencies"]) == 1024              # 2048 bins of 4 ps
    assert abs(brightest(reference)[2] - 0.504) <= 0.03


def test_the_histograms_field_is_every_dft_bin_without_an_aliasing_warning(point_capture,
                                                                          caplog):
    """The 16 x 16 wall (6.7 cm spacing) aliases above 3.75 cycles/m for a confocal scan,
    far below the histograms' 125 cycles/m: the fft transform warns for that band, the
    reference field must not (it leaves every logger's filters alone), and its values are
    the plain DFT of the histograms, computed here independently."""
    _, capture = point_capture
    with caplog.at_level("WARNING"):
        field = histogram_field(capture)
    assert not [r for r in caplog.records if r.levelname == "WARNING"]
    assert not logging_filters()
    n, dt = capture.n_bins, capture.delta_t
    assert field.n_frequencies == n // 2
    np.testing.assert_allclose(field.frequencies, np.arange(1, n // 2 + 1) / (n * dt))
    h = np.asarray(capture.H, dtype=float)          # (t, x, y); the field is (f, y, x)
    t = capture.t_start + (np.arange(n) + 0.5) * dt
    for k in (0, 7, n // 2 - 1):
        phase = np.exp(-2j * np.pi * field.frequencies[k] * t)
        expected = np.einsum("txy,t->yx", h, phase) * dt
        scale = np.abs(expected).max()
        assert scale > 0
        assert np.abs(np.asarray(field.values[k]) - expected).max() < 1e-9 * scale


def logging_filters() -> list[object]:
    """Filters on the logger of the transform's frequency checks (none are left behind)."""
    return list(logging.getLogger("nlosfw.transform.frequencies").filters)

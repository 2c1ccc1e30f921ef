"""``python -m nlosfw image FILE`` and ``model=none``: one capture read, preprocessed and
imaged, with the views a researcher looks at; ``stop_after=reconstruct`` draws its figures.

The capture is a confocal scan of one point scatterer written by the test (the project's
HDF5 writer), so where the image must put it is known: at the point's depth and lateral
position, and the capture's time profile peaks at the round trip of the wall samples that
see most of its light.
"""

import json
from pathlib import Path

import numpy as np
import pytest

import nlosfw
from nlosfw.capture.hdf5 import write_capture
from nlosfw.cli import main
from nlosfw.cli.image_command import image_overrides
from nlosfw.common import yaml_safe
from nlosfw.image.reconstruction import Reconstruction
from nlosfw.image.reconstruction_io import read_reconstruction
from nlosfw.report.views import masked_depth_map, round_trip_path, time_profile
from tests.planned import TINY, planned

POINT = np.array([0.1, -0.05, 0.6])
BIN = 0.008
SCENE = {
    "name": "point_confocal",
    "wall": {"size": [1.0, 1.0], "resolution": [16, 16], "center": [0.0, 0.0]},
    "capture": {"type": "confocal", "laser_position": [-0.5, 0.0, 0.25],
                "sensor_position": [-0.5, 0.0, 0.25], "device_legs": False},
    "time": {"bins": 320, "bin_width": BIN, "start": 0.0},
    "noise": {"model": "none"},
    "geometry": [{"type": "point", "position": POINT.tolist(), "albedo": 0.01}],
}
#: Files every run writes whatever it computes (its record, not its results).
BOOKKEEPING = {"config.yaml", "metrics.json", "metrics.schema.json", "run.log",
               ".nlosfw-run.json"}
#: What ``image FILE`` promises, and nothing else.
PROMISED = {"reconstructions/true.hdf5", "figures/front_true.png", "figures/depth_true.png",
            "figures/slices_true.png", "figures/time_profile.png", "report.html"}


@pytest.fixture(scope="module")
def point_capture(tmp_path_factory):
    capture = nlosfw.simulate_scene(SCENE)
    path = tmp_path_factory.mktemp("capture") / "point scan.hdf5"
    write_capture(path, capture)
    return path, capture


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("COLUMNS", "200")
    return tmp_path


def written(run_dir: Path) -> set[str]:
    """The run's files, relative, without its bookkeeping and Hydra's record."""
    return {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()
            and not p.relative_to(run_dir).as_posix().startswith(".hydra/")
            and p.name not in BOOKKEEPING}


def test_image_writes_the_volume_views_and_report_and_finds_the_point(workdir, point_capture,
                                                                      capsys):
    path, _ = point_capture
    status = main(["image", str(path), "hydra.run.dir=run", "figures.dpi=40"])
    out = capsys.readouterr()
    assert status == 0, out.err
    run = workdir / "run"
    assert written(run) == PROMISED
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "completed" and metrics["run"]["model"] == "none"
    assert "field" not in metrics and "split" not in metrics      # no field model, no split
    assert set(metrics["timings"]) == {"capture", "transform", "reconstruct", "report", "total"}
    recon = read_reconstruction(run / "reconstructions" / "true.hdf5")
    volume, voxels = recon.as_volume()
    z, y, x = np.unravel_index(np.argmax(volume), volume.shape)
    spacing = float(np.diff(recon.depths)[0])
    assert abs(voxels[z, y, x, 2] - POINT[2]) <= 2 * spacing + 1e-9
    assert abs(voxels[z, y, x, 0] - POINT[0]) <= 1 / 16 + 1e-9     # one wall sample
    assert abs(voxels[z, y, x, 1] - POINT[1]) <= 1 / 16 + 1e-9
    page = (run / "report.html").read_text()
    assert "<h2>Views</h2>" in page and "front_true.png" in page and "time_profile.png" in page
    # no imager given: the one picked for a confocal scan on a regular grid, and the log
    # says so in one line
    assert "capture point scan.hdf5 (format nlosfw) · imager lct" in page
    assert metrics["run"]["imager"] == "lct"
    used = yaml_safe.load((run / "config.yaml").read_text())
    assert used["imager"]["name"] == "lct" and used["reconstruction"]["pick_imager"] is True
    assert ("imager lct picked for a confocal scan on a regular grid"
            in (run / "run.log").read_text())
    assert "thesis_two_planes" not in page and "simulator" not in page  # no default scene
    assert "done (completed)" in out.out


def test_image_picks_fft_for_a_single_spot_capture_and_an_imager_given_wins(workdir, capsys):
    single = {**SCENE, "name": "point_single_spot",
              "capture": {**SCENE["capture"], "type": "single_spot"}}
    path = workdir / "single.hdf5"
    write_capture(path, nlosfw.simulate_scene(single))
    assert main(["image", str(path), "hydra.run.dir=single", "figures.enabled=false"]) == 0
    log = (workdir / "single" / "run.log").read_text()
    assert "imager fft picked for a single_spot capture" in log
    metrics = json.loads((workdir / "single" / "metrics.json").read_text())
    assert metrics["run"]["imager"] == "fft"
    # an imager given explicitly is used as it is, and nothing is picked
    assert main(["image", str(path), "imager=rsd", "hydra.run.dir=given",
                 "figures.enabled=false", "reconstruction.n_depths=4"]) == 0
    assert "picked" not in (workdir / "given" / "run.log").read_text()
    metrics = json.loads((workdir / "given" / "metrics.json").read_text())
    assert metrics["run"]["imager"] == "rsd"
    capsys.readouterr()


def test_model_none_by_overrides_stops_after_reconstruct_with_its_figures(workdir,
                                                                         point_capture,
                                                                         capsys):
    path, _ = point_capture
    status = main([f"capture.path='{path}'", "model=none", "stop_after=reconstruct",
                   "hydra.run.dir=run", "figures.dpi=40", "output.keep=[]"])
    out = capsys.readouterr()
    assert status == 0, out.err
    run = workdir / "run"
    assert written(run) == PROMISED - {"reconstructions/true.hdf5"}
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "stopped" and metrics["run"]["stopped_after"] == "reconstruct"
    assert "done (stopped after reconstruct)" in " ".join(out.out.split())


def test_a_field_model_run_stopped_after_reconstruct_draws_what_it_computed(workdir,
                                                                           point_capture):
    path, _ = point_capture
    out = nlosfw.run([f"capture.path='{path}'", "model=interp", "stop_after=reconstruct",
                      "figures.dpi=40", "output.keep=[]", "reconstruction.n_depths=6",
                      "reconstruction.single_frequency_images=0"], output_dir=workdir / "run")
    assert out.metrics.status == "stopped"
    figures = {p.name for p in (workdir / "run" / "figures").iterdir()}
    sources = ("true", "raw", "interp")
    assert figures == {"reconstructions.png", "time_profile.png",
                       *(f"{v}_{s}.png" for s in sources for v in ("front", "depth", "slices"))}
    assert "No figures" not in (workdir / "run" / "report.html").read_text()


@pytest.mark.parametrize(("args", "message"), [
    (["model=none", "split.spatial_step=4"], "error: split: model=none images the whole "
                                             "capture and splits nothing"),
    (["-m", "model=none", "split.spatial_step=1,4"], "error: split: model=none"),
    (["model=none", "+compare.nn={name:nearest}"], "error: compare: model=none fits no "
                                                  "field model"),
    (["model=none", "stop_after=fit"], "error: stop_after: model=none fits and predicts "
                                       "nothing"),
    (["image", "missing.mat"], "error: missing.mat: no such capture file"),
    (["image"], "error: image needs a capture file first"),
    (["image", "{capture}", "model=interp"], "error: model: image sets it"),
])
def test_what_model_none_cannot_do_is_one_line_exit_2_nothing_written(
        workdir, point_capture, capsys, args, message):
    path, _ = point_capture
    given = [a.replace("{capture}", str(path)) for a in args]
    if given[:1] != ["image"]:  # Hydra's flags (-m) first, then the overrides
        flags = [a for a in given if a.startswith("-")]
        given = [*flags, f"capture.path='{path}'", *(a for a in given if a not in flags)]
    status = main(given)
    err = capsys.readouterr().err
    assert status == 2
    assert err.strip().count("\n") == 0 and message in err, err
    assert not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


def test_masked_depth_map_is_blank_where_there_is_no_signal():
    depths = np.array([0.4, 0.5, 0.6, 0.7])
    ys, xs = np.mgrid[0:5, 0:6] * 0.1
    voxels = np.stack(np.broadcast_arrays(xs[None], ys[None], depths[:, None, None]), axis=-1)
    intensity = np.full((4, 5, 6), 1e-4)
    intensity[2, 1:3, 1:4] = 1.0        # a surface at 0.6 m
    intensity[1, 4, 5] = 0.5            # a fainter one at 0.5 m, above the 10 % cut
    intensity[3, 0, 0] = 0.05           # below it: no signal
    depth = masked_depth_map(Reconstruction(intensity=intensity, voxels=voxels))
    expected = np.full((5, 6), np.nan)
    expected[1:3, 1:4] = 0.6
    expected[4, 5] = 0.5
    np.testing.assert_array_equal(depth, expected)


def test_time_profile_peaks_at_the_round_trip_to_the_nearest_wall_sample(point_capture):
    _, capture = point_capture
    path, counts = time_profile(capture)
    assert path.shape == counts.shape == (capture.n_bins,)
    assert counts.sum() == pytest.approx(float(np.sum(capture.H, dtype=np.float64)))
    # confocal: wall sample s sees the point at path 2 r, r = |p - s|, with the radiance
    # cos^2 / r^4 (cos = z / r at the wall: nlosfw.simulate.physics); binned on the same axis
    r = np.linalg.norm(capture.sensor_points - POINT, axis=1)
    edges = np.arange(capture.n_bins + 1) * BIN
    expected, _ = np.histogram(2 * r, bins=edges, weights=(POINT[2] / r) ** 2 / r ** 4)
    peak = edges[np.argmax(expected)] + BIN / 2
    assert abs(path[np.argmax(counts)] - peak) <= 1.5 * BIN
    assert np.corrcoef(counts, expected)[0, 1] > 0.9
    # no device legs in this capture's time axis: a depth's round trip is twice it
    np.testing.assert_allclose(round_trip_path(capture, np.array([0.3, 0.6])), [0.6, 1.2])


def test_image_stands_for_capture_path_model_none_keeping_the_volume(tmp_path):
    path = tmp_path / "it's [a] scan.mat"
    path.write_bytes(b"")
    quoted = "capture.path='" + str(path.resolve()).replace("'", "\\'") + "'"
    assert image_overrides([str(path)]) == [quoted, "model=none",
                                            "output.keep=[reconstructions]",
                                            "reconstruction.pick_imager=true"]
    # any imager option (or the pick's own) turns the pick off
    for given in ("imager=fft", "+imager=fk", "imager.falloff=diffuse",
                  "reconstruction.pick_imager=false"):
        assert "reconstruction.pick_imager=true" not in image_overrides([str(path), given])
    # Hydra's flags go first (they must precede the overrides); output.keep given wins
    assert image_overrides([str(path), "imager=lct", "-m", "-cn", "config",
                            "output.keep=[]"]) == [
        "-m", "-cn", "config", quoted, "model=none", "imager=lct", "output.keep=[]"]


@pytest.mark.parametrize(("capture_type", "imager", "what"), [
    ("confocal", "lct", "a confocal scan on a regular grid"),
    ("single_spot", "fft", "a single_spot capture")])
def test_a_scene_run_picks_the_imager_for_its_capture_type(capture_type, imager, what):
    plan = planned([*TINY, f"scene.capture.type={capture_type}", "imager=rsd",
                    "reconstruction.pick_imager=true"])
    assert plan.imager.name == imager and plan.selected("imager") == imager
    assert plan.imager_note.startswith(f"imager {imager} picked for {what}")
    assert plan.used_config()["imager"]["name"] == imager
    assert plan.config["imager"]["name"] == "rsd"        # the composed one, as it was given
    # no reference picture unless asked for, whatever the imager picked
    assert plan.settings.reconstruction.histogram_reference is False
    kept = planned([*TINY, f"scene.capture.type={capture_type}", "imager=rsd"])
    assert kept.imager.name == "rsd" and kept.imager_note == ""

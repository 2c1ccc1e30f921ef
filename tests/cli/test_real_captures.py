"""Runs from capture files on the command line: the acceptance test of the LCT format (a
synthetic confocal capture with a direct reflection reconstructs from nothing but
``capture.path=<file>.mat``, exactly as the same capture given as HDF5), labels, the cache,
conversion to HDF5, and bad input refused before any output exists."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.cli import main
from nlosfw.image.reconstruction_io import read_reconstruction
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import layouts

FAST = ["model=interp", "figures.enabled=false", "output.keep=[capture,reconstructions]"]
#: The letter "L" of the acceptance scene: two rectangles 0.5 m from the wall.
LETTER = [{"type": "rectangle", "position": [-0.1, 0.12, 0.5], "size": [0.2, 0.06]},
          {"type": "rectangle", "position": [-0.17, 0.0, 0.5], "size": [0.06, 0.18]}]
DEPTH = 0.5


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


@pytest.fixture(scope="module")
def letter_counts():
    """The letter scanned confocally as in the LCT captures (16 x 16 points over 0.8 m, 4 ps
    bins from the wall), as photon counts; no metadata (as if read from a real file)."""
    config = layouts.lct_scene(resolution=16, bins=1600)
    config["wall"]["size"] = [0.8, 0.8]
    config["geometry"] = LETTER
    capture = AnalyticSimulator().simulate(scene_from_config(config))
    counts = np.rint(capture.H / capture.H.max() * 1000).astype(np.float32)
    return capture.replace(H=counts, scene_info={})


def with_direct_reflection(capture):
    """The direct reflection off the wall at every scan point: a bright peak at t = 0 whose
    tail decays over the first few hundred bins."""
    direct = np.rint(60000 * np.exp(-np.arange(capture.n_bins) / 40.0)).astype(np.float32)
    return capture.replace(H=capture.H + direct[:, None, None])


def run(workdir, name, *args):
    """One in-process run into ``workdir/name``; returns it and its metrics."""
    assert main([*args, f"hydra.run.dir={workdir / name}"]) == 0
    return workdir / name, json.loads((workdir / name / "metrics.json").read_text())


def test_lct_file_reconstructs_from_its_path_alone_like_the_same_capture_as_hdf5(
        workdir, letter_counts):
    mat = layouts.write_lct(workdir / "data_l.mat", with_direct_reflection(letter_counts),
                            dtype=np.uint16)
    hdf5 = write_capture(workdir / "data_l.hdf5", letter_counts, nlosfw_attributes=False)
    from_mat, m_mat = run(workdir, "mat", f"capture.path={mat}", *FAST)
    from_hdf5, m_hdf5 = run(workdir, "hdf5", f"capture.path={hdf5}", *FAST)
    assert (m_mat["capture"]["format"], m_hdf5["capture"]["format"]) == ("lct", "ytal")
    assert [(s["option"], s["source"]) for s in m_mat["capture"]["preprocessing"]] == [
        ("gate", "format")]
    assert m_hdf5["capture"]["preprocessing"] == []
    # the same field, depths and images: the gate removed exactly the direct reflection
    for key in ("n_frequencies", "grid"):
        assert m_mat["transform"][key] == m_hdf5["transform"][key]
    assert m_mat["transform"]["frequency_band"] == pytest.approx(
        m_hdf5["transform"]["frequency_band"], rel=1e-12)
    assert m_mat["reconstruction"]["depths"] == pytest.approx(
        m_hdf5["reconstruction"]["depths"], rel=1e-12)
    for source in ("true", "raw", "interp"):
        a = read_reconstruction(from_mat / f"reconstructions/{source}.hdf5").intensity
        b = read_reconstruction(from_hdf5 / f"reconstructions/{source}.hdf5").intensity
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6 * float(b.max()))
        assert (m_mat["reconstruction"]["sources"][source]["ssim"]
                == pytest.approx(m_hdf5["reconstruction"]["sources"][source]["ssim"]))
    # and it shows the letter where it is
    recon = read_reconstruction(from_mat / "reconstructions/true.hdf5")
    intensity, voxels = recon.as_volume()
    x, y, z = voxels[np.unravel_index(int(np.argmax(intensity)), intensity.shape)]
    step = float(np.diff(recon.depths).max())
    assert abs(z - DEPTH) <= step
    assert -0.2 - 0.05 <= x <= 0.0 + 0.05 and -0.09 - 0.05 <= y <= 0.15 + 0.05
    # without the gate the direct reflection swamps the image near the wall
    ungated, _ = run(workdir, "ungated", f"capture.path={mat}", "capture.gate.bins=0", *FAST)
    bad = read_reconstruction(ungated / "reconstructions/true.hdf5")
    bad_intensity, bad_voxels = bad.as_volume()
    z_bad = bad_voxels[np.unravel_index(int(np.argmax(bad_intensity)), bad_intensity.shape)][2]
    assert abs(z_bad - DEPTH) > 2 * step


def test_a_file_run_is_labelled_with_its_file_and_format(workdir, letter_counts, capsys,
                                                         monkeypatch):
    from nlosfw.report import figures

    titles = []
    original = figures.reconstruction_figure

    def recording(recons, scores, truth, title, *labels):
        titles.append(title)
        return original(recons, scores, truth, title, *labels)

    monkeypatch.setattr(figures, "reconstruction_figure", recording)
    mat = layouts.write_lct(workdir / "data_l.mat", letter_counts)
    out, metrics = run(workdir, "labelled", f"capture.path={mat}", "model=interp",
                       "reconstruction.single_frequency_images=0")
    stdout = capsys.readouterr().out
    assert metrics["run"]["scene"] is None and metrics["run"]["simulator"] is None
    assert metrics["run"]["capture_file"] == str(mat)
    assert metrics["run"]["capture_format"] == "lct"
    assert len(titles) == 1 and titles[0].startswith(
        "capture data_l.mat (format lct) · model interp · imager fft\nall ")
    assert "(format lct)" in stdout and "gate (format default)" in stdout
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert "scene" not in config and "simulator" not in config
    for text in (stdout, (out / "metrics.json").read_text(), (out / "config.yaml").read_text()):
        assert "thesis_two_planes" not in text and "analytic" not in text


def test_the_cache_key_covers_the_file_and_the_options(workdir, letter_counts):
    mat = layouts.write_lct(workdir / "data_l.mat", letter_counts)
    stop = ["stop_after=transform", *FAST]
    _, first = run(workdir, "a", f"capture.path={mat}", *stop)
    _, again = run(workdir, "b", f"capture.path={mat}", *stop)
    _, gated = run(workdir, "c", f"capture.path={mat}", "capture.gate.bins=700", *stop)
    assert (first["transform"]["cache_hit"], again["transform"]["cache_hit"],
            gated["transform"]["cache_hit"]) == (False, True, False)
    changed = layouts.write_lct(workdir / "other.mat", letter_counts.replace(
        H=letter_counts.H * 2))
    _, other = run(workdir, "d", f"capture.path={changed}", *stop)
    assert other["transform"]["cache_hit"] is False


def test_stop_after_capture_converts_a_file_to_ytal_hdf5(workdir, letter_counts):
    mat = layouts.write_lct(workdir / "data_l.mat", with_direct_reflection(letter_counts))
    out, _ = run(workdir, "convert", f"capture.path={mat}", "stop_after=capture")
    converted = read_capture(out / "capture.hdf5")
    np.testing.assert_array_equal(converted.H[:600], 0)
    np.testing.assert_array_equal(converted.H[600:], letter_counts.H[600:])
    assert converted.scene_info["original_format"] == "MAT_LCT"
    assert converted.scene_info["preprocessing"][0]["option"] == "gate"
    # and the converted file runs with nothing more to say
    _, again = run(workdir, "from_hdf5", f"capture.path={out / 'capture.hdf5'}",
                   "stop_after=capture")
    assert again["capture"]["format"] == "nlosfw" and again["capture"]["preprocessing"] == []


def _mat(tmp, name, **variables):
    return layouts.write_mat5(tmp / name, variables)


@pytest.mark.parametrize(("make", "args", "message"), [
    (lambda t: _mat(t, "cut.mat", rect_data=np.zeros((4, 4, 8))), [],
     "error: {path}: not a capture file of any supported format; supported: fk, lct, nlosfw, "
     "wisconsin, ytal, znlos (force one with capture.format=NAME)"),
    (lambda t: _mat(t, "cut.mat", rect_data=np.zeros((4, 4, 8))), ["capture.format=lct"],
     "error: {path}: no variable 'width' (expected rect_data, the histograms [N, N, T]"),
    (lambda t: _mat(t, "neg.mat", rect_data=np.zeros((4, 4, 8)), width=np.array([[-0.4]])), [],
     "error: {path}: variable 'width' is -0.4; expected a positive number of metres"),
    (lambda t: _mat(t, "ok.mat", rect_data=np.zeros((4, 4, 900)), width=np.array([[0.4]])),
     ["capture.gate.bins=900"],
     "error: capture.gate.bins: 900 bins is past the end of the histogram (900 bins"),
    (lambda t: _mat(t, "ok.mat", rect_data=np.zeros((4, 4, 900)), width=np.array([[0.4]])),
     ["capture.format=fk"], "error: {path}: no variable 'meas' (expected meas, the histograms"),
    (lambda t: _mat(t, "ok.mat", rect_data=np.zeros((4, 4, 900)), width=np.array([[0.4]])),
     ["capture.format=nope"], "error: capture.format: unknown capture format 'nope'; valid: "),
    (lambda t: _mat(t, "ok.mat", rect_data=np.zeros((4, 4, 900)), width=np.array([[0.4]])),
     ["capture.tofgrid=missing.mat"], "error: capture.tofgrid: file not found: missing.mat"),
])
def test_bad_files_and_options_one_line_exit_2_nothing_written(workdir, capsys, make, args,
                                                              message):
    path = make(workdir)
    assert main([f"capture.path={path}", *args, *FAST]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message.format(path=path)), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (workdir / "outputs").exists()


def test_a_format_without_a_file_is_refused(workdir, capsys):
    assert main(["scene=tiny", "capture.format=lct", *FAST]) == 2
    assert capsys.readouterr().err == ("error: capture.format: forces the format of "
                                       "capture.path: give capture.path too\n")
    assert not (workdir / "outputs").exists()


def test_tofgrid_of_another_shape_is_refused_before_any_output(workdir, capsys):
    capture = AnalyticSimulator().simulate(scene_from_config(layouts.fk_scene()))
    meas, _ = layouts.write_fk(workdir / "statue", capture)
    tof = layouts.write_mat73(workdir / "statue" / "tof.mat", {"tofgrid": np.zeros((16, 16))})
    assert main([f"capture.path={meas}", *FAST]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: capture.tofgrid: {tof}: variable 'tofgrid' has shape [16, 16]; "
                   f"expected [8, 8], the scan grid of {meas}\n")
    assert not (workdir / "outputs").exists()


def test_a_simulated_run_is_preprocessed_too(workdir):
    out, metrics = run(workdir, "sim", "scene=tiny", "capture.bin=2", "capture.gate.bins=3",
                       "stop_after=capture")
    assert metrics["capture"]["shape"][1:] == [8, 8]
    assert [s["option"] for s in metrics["capture"]["preprocessing"]] == ["gate", "bin"]
    assert metrics["run"]["scene"] == "tiny" and "capture_file" not in metrics["run"]
    assert Path(out / "capture.hdf5").is_file()


def test_a_wisconsin_file_runs_on_the_grid_its_points_form(workdir):
    capture = AnalyticSimulator().simulate(scene_from_config(layouts.wisconsin_scene()))
    path = layouts.write_wisconsin(workdir / "letter.mat", capture)
    _, metrics = run(workdir, "wis", f"capture.path={path}", "stop_after=transform", *FAST)
    assert metrics["capture"]["format"] == "wisconsin"
    assert [(s["option"], s["source"]) for s in metrics["capture"]["preprocessing"]] == [
        ("grid", "automatic")]
    assert metrics["capture"]["shape"] == [400, 8, 8] and metrics["transform"]["grid"] == [8, 8]

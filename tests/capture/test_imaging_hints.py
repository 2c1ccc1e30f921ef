"""Imaging hints: the settings a capture states travel from it to the transient imagers,
which use them unless their own options are set; no capture gets any from its name."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from nlosfw import load_capture
from nlosfw.capture.hdf5 import read_capture, write_capture
from nlosfw.capture.hints import HINTS_KEY, ImagingHints, capture_hints, with_hints
from nlosfw.common import yaml_safe
from nlosfw.image.lct import LCTImager, LCTImagerConfig
from nlosfw.image.transient import Falloff
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from nlosfw.transform.fft import FFTTransform
from nlosfw.transform.field import Band
from nlosfw.transform.field_io import read_phasor_field, write_phasor_field


@pytest.fixture(scope="module")
def capture():
    config = layouts.lct_scene(resolution=8, bins=1700)
    return AnalyticSimulator().simulate(scene_from_config(config))


@pytest.mark.parametrize("stem", ["data_diffuse_s", "data_dot_chart_40cm",
                                  "data_resolution_chart_40cm", "scan"])
def test_no_capture_carries_settings_from_its_name(tmp_path, capture, stem):
    """A capture's settings never come from its file's name: the names of the published
    LCT scenes carry none, like any other."""
    path = layouts.write_lct(tmp_path / f"{stem}.mat", capture)
    assert capture_hints(load_capture(path)) == ImagingHints()


STATED = ImagingHints(falloff="retroreflective", snr=0.8, origin="stated by the capture")


def test_imagers_use_the_stated_hints_unless_set_explicitly(capture):
    field = FFTTransform().transform(with_hints(capture, STATED))
    assert field.imaging_hints.snr == 0.8 and HINTS_KEY not in field.metadata
    voxels = fixtures.aligned_voxels(field.wall_xyz, np.linspace(0.5, 0.7, 5))
    hinted = LCTImager().reconstruct(field, voxels)
    explicit = LCTImager(LCTImagerConfig(falloff=Falloff.retroreflective, snr=0.8)
                         ).reconstruct(field, voxels)
    overridden = LCTImager(LCTImagerConfig(falloff=Falloff.diffuse, snr=0.08)
                           ).reconstruct(field, voxels)
    assert (hinted.metadata["falloff"], hinted.metadata["snr"]) == ("retroreflective", 0.8)
    assert hinted.metadata["settings"] == "stated by the capture"
    np.testing.assert_array_equal(hinted.intensity, explicit.intensity)
    assert (overridden.metadata["falloff"], overridden.metadata["snr"]) == ("diffuse", 0.08)
    assert "the snr option" in overridden.metadata["settings"]
    difference = np.linalg.norm(overridden.intensity - hinted.intensity)
    assert difference > 0.01 * np.linalg.norm(hinted.intensity)


def test_bad_hints_in_a_file_are_ignored():
    hints = ImagingHints.from_mapping({"falloff": "shiny", "snr": -1, "depth_window": [2, 1]})
    assert hints == ImagingHints()


# ------------------------------------------------- typed attributes, and older files' keys
def test_fields_and_captures_carry_typed_attributes_not_metadata_keys(tmp_path, capture):
    path = layouts.write_lct(tmp_path / "scan.mat", capture)
    loaded = with_hints(load_capture(path), STATED)
    assert loaded.imaging_hints.snr == 0.8 and HINTS_KEY not in loaded.scene_info
    field = FFTTransform().transform(loaded).replace(zero_filled=True, depth_range=(0.4, 0.6))
    assert not {"band", "imaging_hints", "zero_filled", "depth_range"} & set(field.metadata)
    again = read_phasor_field(write_phasor_field(tmp_path / "field.hdf5", field))
    assert again.band == field.band and again.imaging_hints == field.imaging_hints
    assert again.zero_filled and again.depth_range == (0.4, 0.6)
    assert again.metadata == field.metadata
    # a capture file keeps the hints where y-tal keeps free metadata, and reads them back
    written = write_capture(tmp_path / "capture.hdf5", loaded)
    with h5py.File(written) as f:
        stored = yaml_safe.load(f["scene_info"][()])
    assert stored[HINTS_KEY]["snr"] == 0.8
    assert read_capture(written).imaging_hints == loaded.imaging_hints


def test_a_field_file_of_the_older_layout_reads_its_metadata_keys_as_attributes(tmp_path):
    """Before they were typed, the band, the hints, the zero filling and the depth range
    were keys of the field's metadata: such a file reads them into the attributes."""
    field = FFTTransform().transform(fixtures.point_capture())
    path = tmp_path / "old.hdf5"
    with h5py.File(path, "w") as f:
        f.attrs["nlosfw_type"] = "PhasorField"
        f.attrs["format_version"] = 1
        f.create_dataset("values", data=field.values)
        f.create_dataset("frequencies", data=field.frequencies)
        f.create_dataset("wall_xyz", data=field.wall_xyz)
        string = h5py.string_dtype("utf-8")
        f.create_dataset("geometry", data=yaml_safe.dump(field.geometry.to_dict()), dtype=string)
        f.create_dataset("metadata", dtype=string, data=yaml_safe.dump({
            "transform": "fft", "zero_filled": True, "depth_range": [0.3, 0.9],
            "band": {"grid_spacing": 0.1, "spatial_limit": 5.0, "option": "transform.f_max",
                     "aliases": True},
            HINTS_KEY: {"falloff": "diffuse", "snr": 0.08, "origin": "a test"}}))
    old = read_phasor_field(path)
    assert old.metadata == {"transform": "fft"}
    assert old.zero_filled and old.depth_range == (0.3, 0.9)
    assert old.band == Band(option="transform.f_max", grid_spacing=0.1, spatial_limit=5.0,
                            aliases=True)
    assert old.imaging_hints == ImagingHints(falloff="diffuse", snr=0.08, origin="a test")

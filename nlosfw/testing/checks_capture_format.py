"""Conformance checks of capture formats (kind ``capture_format``).

A format is checked on a file in its layout written from a known capture: by its own
:meth:`~nlosfw.capture.CaptureFormat.write` when it declares ``writable``, else by the
kit's writer of its published layout (:mod:`nlosfw.testing.layouts`, the built-in
formats). Reading that file must give the known capture's histograms, wall points, bin
width and time origin, and the brightest bin must lie at the closed-form path length of
the hidden patch. Detection must claim that file and nothing else: no file of another
format's layout, no unrelated file.
"""

from __future__ import annotations

import tempfile
import unittest
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np
import numpy.typing as npt

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.common.errors import DataError, NlosfwError
from nlosfw.plugins.capabilities import Capability as C
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import layouts
from nlosfw.testing.checks_common import one_line_error
from nlosfw.testing.layouts import known_captures, write_sample
from nlosfw.testing.selection import requires


@contextmanager
def foreign_files(spec: PluginSpec, others: bool = True) -> Iterator[list[Path]]:
    """Files ``spec`` must not claim: unrelated bytes, HDF5 and MATLAB files holding other
    variables, and (``others``) a file of every other format the kit can write."""
    from nlosfw.plugins.manager import load_plugins

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        files = [root / "empty.dat", root / "text.txt", root / "noise.bin"]
        files[0].write_bytes(b"")
        files[1].write_text("time,counts\n0,1\n")
        files[2].write_bytes(np.random.default_rng(0).bytes(4096))
        import h5py

        with h5py.File(root / "other.h5", "w") as f:
            f["image"] = np.zeros((4, 4))
        files.append(root / "other.h5")
        files.append(layouts.write_mat5(root / "other5.mat", {"image": np.zeros((4, 4, 4))}))
        files.append(layouts.write_mat73(root / "other73.mat", {"image": np.zeros((4, 4, 4))}))
        registry = load_plugins().registry
        for other in registry.specs(spec.kind) if others else ():
            if other.name == spec.name or other.missing_requirements():
                continue
            try:
                captures = known_captures(other)
            except unittest.SkipTest:
                continue
            folder = root / other.name
            folder.mkdir()
            files.append(write_sample(other, other.create({}), captures[0], folder))
        yield files


def _assert_same_capture(spec: PluginSpec, got: Capture, known: Capture) -> None:
    """Histograms, wall points, bin width and time origin (path minus device legs) agree."""
    name = spec.qualified_name
    assert got.kind is known.kind, f"{name}: read a {got.kind.value} capture, wrote a " \
                                   f"{known.kind.value} one"
    np.testing.assert_allclose(got.sensor_points, known.sensor_points, atol=1e-9,
                               err_msg=f"{name}: the wall points moved")
    np.testing.assert_allclose(got.H.reshape(got.n_bins, -1), known.H.reshape(known.n_bins, -1),
                               rtol=1e-6, atol=0, err_msg=f"{name}: the histograms changed")
    assert np.isclose(got.delta_t, known.delta_t, rtol=1e-9), (
        f"{name}: bin width {got.delta_t} m read, {known.delta_t} m written")
    origin_got = got.t_start - got.geometry.device_path(got.sensor_points)
    origin_known = known.t_start - known.geometry.device_path(known.sensor_points)
    np.testing.assert_allclose(origin_got, origin_known, atol=1e-9, err_msg=(
        f"{name}: the time origin (t_start minus the device legs) moved"))


def _assert_peak_at_closed_form(spec: PluginSpec, got: Capture, target: npt.ArrayLike) -> None:
    """The brightest bin of the wall point nearest the hidden patch lies within two bins of
    the closed-form path laser spot -> patch -> wall point (device legs added)."""
    points = got.sensor_points
    k = int(np.argmin(np.linalg.norm(points[:, :2] - np.asarray(target)[:2], axis=1)))
    p = np.asarray(target, dtype=float)
    x = points[k]
    laser = x if got.kind is CaptureKind.CONFOCAL else got.laser_point
    path = np.linalg.norm(p - laser) + np.linalg.norm(p - x)
    path += float(got.geometry.device_path(x[None])[0])
    peak = got.bin_centers[int(np.argmax(got.H.reshape(got.n_bins, -1)[:, k]))]
    assert abs(peak - path) <= 2 * got.delta_t, (
        f"{spec.qualified_name}: brightest bin at path {peak:.4f} m, closed form {path:.4f} m "
        f"(bin {got.delta_t:.4g} m): wrong units or time origin")


@requires(C.READABLE)
def check_reads_its_layout(spec: PluginSpec) -> None:
    """A file written in the format's layout from a known analytic capture reads back as that
    capture: histograms, wall points, bin width (metres), time origin; the brightest bin at
    the closed-form path length of the hidden patch; the transient's shape from the header,
    when the format gives one, is the one read."""
    from nlosfw.testing.fixtures import TINY_TARGET

    fmt = spec.create(dict(spec.test_config))
    for known in known_captures(spec):
        with tempfile.TemporaryDirectory() as tmp:
            path = write_sample(spec, fmt, known, Path(tmp))
            got = fmt.read(path)
            header = fmt.transient_shape(path)
        _assert_same_capture(spec, got, known)
        if header is not None:
            bins, sensors, lasers = header
            read = (got.n_bins, got.H.size // got.n_bins)
            assert (bins, sensors * lasers) == read, (
                f"{spec.qualified_name}: transient_shape says {bins} bins x {sensors * lasers} "
                f"samples, the file holds {read[0]} x {read[1]}")
        target = (known.scene_info.get("scene") or {}).get("geometry", [{}])[0].get(
            "position", TINY_TARGET)
        _assert_peak_at_closed_form(spec, got, target)


@requires(C.READABLE)
def check_detects_only_its_files(spec: PluginSpec) -> None:
    """Detection (from content, whatever the file's name) claims a file in the format's layout
    and nothing else: no unrelated file, no file of another format, and never raises (nor
    does the header's transient shape)."""
    fmt = spec.create(dict(spec.test_config))
    known = known_captures(spec)[0]
    with tempfile.TemporaryDirectory() as tmp:
        own = write_sample(spec, fmt, known, Path(tmp))
        assert fmt.detect(own) is True, f"{spec.qualified_name}: does not recognise its own file"
    with foreign_files(spec) as files:
        for path in files:
            try:
                claimed = fmt.detect(path)
                fmt.transient_shape(path)
            except Exception as err:  # detection must never raise
                raise AssertionError(f"{spec.qualified_name}: detect or transient_shape "
                                     f"({path.name}) raised {type(err).__name__}: {err}"
                                     ) from err
            where = path.relative_to(path.parents[1])
            assert claimed is False, f"{spec.qualified_name}: claims {where}"


@requires(C.READABLE)
def check_foreign_file_is_a_one_line_error(spec: PluginSpec) -> None:
    """Reading an unrelated file (bytes, text, HDF5 or MATLAB files holding other variables)
    raises a one-line error naming it."""
    fmt = spec.create(dict(spec.test_config))
    with foreign_files(spec, others=False) as files:
        for path in files:
            text = one_line_error(spec, f"reading {path.name}", partial(fmt.read, path),
                                  NlosfwError)
            assert path.name in text, f"{spec.qualified_name}: the error must name the file: " \
                                      f"{text!r}"


@requires(C.WRITABLE)
def check_round_trip(spec: PluginSpec) -> None:
    """What the format writes it reads back unchanged (every field), it never overwrites a
    file, and a failed write leaves nothing behind."""
    fmt = spec.create(dict(spec.test_config))
    for known in known_captures(spec):
        with tempfile.TemporaryDirectory() as tmp:
            path = fmt.write(Path(tmp) / "sample.dat", known)
            got = fmt.read(path)
            for field in ("H", "sensor_grid_xyz", "laser_grid_xyz", "sensor_grid_normals",
                          "laser_grid_normals", "sensor_xyz", "laser_xyz"):
                a, b = getattr(got, field), getattr(known, field)
                assert (a is None) == (b is None), f"{spec.qualified_name}: {field} lost"
                if a is not None:
                    np.testing.assert_array_equal(a, b, err_msg=f"{spec.qualified_name}: {field}")
            for field in ("H_format", "sensor_grid_format", "laser_grid_format", "delta_t",
                          "t_start", "t_accounts_first_and_last_bounces", "scene_info"):
                assert getattr(got, field) == getattr(known, field), (
                    f"{spec.qualified_name}: {field} changed in a round trip")
            before = path.read_bytes()
            one_line_error(spec, "writing over an existing file",
                           partial(fmt.write, path, known), DataError)
            assert path.read_bytes() == before, f"{spec.qualified_name}: overwrote a file"
            assert sorted(p.name for p in Path(tmp).iterdir()) == ["sample.dat"], (
                f"{spec.qualified_name}: left files behind")


CAPTURE_FORMAT_CHECKS = (
    check_reads_its_layout,
    check_detects_only_its_files,
    check_foreign_file_is_a_one_line_error,
    check_round_trip,
)

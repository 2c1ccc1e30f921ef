"""Conformance checks for every imager plugin (see :mod:`nlosfw.testing.checks_common`).

Fields are exact point-scatterer fields (:func:`nlosfw.testing.fixtures.point_field`)
on a NON-square 12 x 16 wall of spacing 1/16 m, a Gaussian band of 9 weighted
frequencies around 4 cycles/m; voxels are planes parallel to the wall whose
(x, y) are the wall samples (valid for every kind of imager):

* a point is focused to its voxel within one voxel in x, y and depth, for
  single-spot and confocal fields, with and without device legs in the phase;
* the image agrees with the plain reference RSD of
  :func:`nlosfw.testing.reference.naive_rsd` (normalised correlation >= 0.99),
  on a defocused plane (a structured image, not just a spot);
* two points 1 m away, two shortest wavelengths of the band apart, are resolved (the
  image between them dips below 0.8 of the weaker peak);
* moving the point parallel to the wall moves the peak by the same number of voxels;
* voxels at or behind the wall give a one-line DataError; output shapes follow the voxels;
* ``point_voxels``: a plain voxel list (N, 3) around the point gives the reference RSD's
  values there (normalised correlation >= 0.99) and peaks at the point;
* ``progress``: ``reconstruct(..., on_progress=...)`` reports (done, total) with done
  non-decreasing up to total, and gives the same image as without the callback.

Imagers declare the geometries they image (``single_spot``, ``confocal``; each check
runs once per declared one), the voxel layouts they accept (``plane_voxels``,
``point_voxels``), and ``rsd`` when their image is the Rayleigh-Sommerfeld image (the
two checks against the reference RSD need it; the classical lct, fk and fbp do not
declare it).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing import fixtures, reference
from nlosfw.testing.checks_common import one_line_error
from nlosfw.testing.selection import GEOMETRIES, requires
from nlosfw.transform.field import PhasorField

SHAPE = (12, 16)
SPACING = 1 / 16
DEPTHS = np.round(np.arange(0.40, 0.801, 0.05), 6)
#: (iy, ix, depth index) of the target: an off-centre wall sample at depth 0.6 m.
TARGET_INDEX = (4, 10, 4)


def _target(iy: int, ix: int, iz: int) -> tuple[float, float, float]:
    wall = fixtures.rect_wall_grid(SHAPE, SPACING)
    return (float(wall[iy, ix, 0]), float(wall[iy, ix, 1]), float(DEPTHS[iz]))


def _field(target: tuple[float, float, float], confocal: bool, legs: bool = False,
           shape: tuple[int, int] = SHAPE, n_frequencies: int = 9) -> PhasorField:
    f, w = fixtures.gaussian_band(4.0, 0.75, n=n_frequencies)
    return fixtures.point_field(target, shape=shape, spacing=SPACING, frequencies=f,
                                weights=w, confocal=confocal, device_legs=legs)


def _peak(spec: PluginSpec, field: PhasorField, voxels: np.ndarray) -> tuple[int, ...]:
    recon = spec.create(dict(spec.test_config)).reconstruct(field, voxels)
    intensity = np.asarray(recon.intensity)
    assert intensity.shape == voxels.shape[:-1], (
        f"{spec.qualified_name}: intensity {intensity.shape} for voxels {voxels.shape}")
    assert np.all(np.isfinite(intensity)), f"{spec.qualified_name}: intensity not finite"
    return tuple(int(i) for i in np.unravel_index(np.argmax(intensity), intensity.shape))


@requires(Capability.PLANE_VOXELS, each=GEOMETRIES)
def check_imager_focuses_point(spec: PluginSpec, confocal: bool) -> None:
    """A point scatterer is imaged within one voxel of its position (x, y and depth),
    with and without device legs in the field's phase."""
    voxels = fixtures.aligned_voxels(fixtures.rect_wall_grid(SHAPE, SPACING), DEPTHS)
    iy, ix, iz = TARGET_INDEX
    for legs in (False, True):
        peak = _peak(spec, _field(_target(iy, ix, iz), confocal, legs), voxels)
        off = np.abs(np.array(peak) - np.array((iz, iy, ix)))
        assert np.all(off <= 1), (
            f"{spec.qualified_name}: point at voxel (z, y, x) = {(iz, iy, ix)} imaged at {peak} "
            f"(confocal={confocal}, device legs in field={legs}); expected within one voxel")


@requires(Capability.PLANE_VOXELS, each=GEOMETRIES)
def check_imager_resolves_two_points(spec: PluginSpec, confocal: bool) -> None:
    """Two point scatterers 1 m from the wall, two shortest wavelengths of the band apart
    laterally, are resolved: on the line through them the image dips below 0.8 of the
    weaker peak (an imager that does not migrate the field fails this)."""
    f, _ = fixtures.gaussian_band(4.0, 0.75)
    apart = int(np.ceil(2.0 / float(f.max()) / SPACING - 1e-9))     # wall samples
    shape = (12, 32)                  # a 2 m aperture along the line: resolution ~ lambda / 2
    row, left = shape[0] // 2, (shape[1] - apart) // 2
    wall = fixtures.rect_wall_grid(shape, SPACING)
    points = [(float(wall[row, ix, 0]), float(wall[row, ix, 1]), 1.0)
              for ix in (left, left + apart)]
    one, two = (_field(p, confocal, shape=shape) for p in points)
    field = one.replace(values=one.values + two.values)
    voxels = fixtures.aligned_voxels(wall, [1.0])[0]
    line = spec.create(dict(spec.test_config)).reconstruct(field, voxels).intensity[row]
    weaker = min(float(line[left]), float(line[left + apart]))
    dip = float(line[left:left + apart + 1].min())
    assert weaker > 0 and dip < 0.8 * weaker, (
        f"{spec.qualified_name}: two points {apart * SPACING:.3f} m apart at 1 m "
        f"(confocal={confocal}) are not resolved: the image between them is {dip:.3g}, the "
        f"weaker peak {weaker:.3g}; expected below 0.8 of it")


@requires(Capability.PLANE_VOXELS, Capability.RSD, each=GEOMETRIES)
def check_imager_matches_reference(spec: PluginSpec, confocal: bool) -> None:
    """Same image as the plain reference RSD (normalised correlation >= 0.99), with and
    without device legs in the field's phase."""
    shape = (8, 10)
    wall = fixtures.rect_wall_grid(shape, SPACING)
    plane = fixtures.aligned_voxels(wall, [0.6])[0]
    target = (float(wall[2, 6, 0]), float(wall[2, 6, 1]), 0.7)    # behind the plane: defocused
    for legs in (False, True):
        field = _field(target, confocal, legs, shape=shape, n_frequencies=5)
        image = spec.create(dict(spec.test_config)).reconstruct(field, plane).intensity
        expected = reference.naive_rsd(field, plane)
        corr = reference.normalised_correlation(image, expected)
        assert corr >= 0.99, (
            f"{spec.qualified_name}: correlation with the reference RSD is {corr:.4f} "
            f"(confocal={confocal}, device legs={legs}); expected >= 0.99")


@requires(Capability.PLANE_VOXELS, each=GEOMETRIES)
def check_imager_translation(spec: PluginSpec, confocal: bool) -> None:
    """Moving the point by (+2, -1) wall samples in (x, y) moves the peak by (+2, -1) voxels."""
    voxels = fixtures.aligned_voxels(fixtures.rect_wall_grid(SHAPE, SPACING), DEPTHS)
    iy, ix, iz = TARGET_INDEX
    first = _peak(spec, _field(_target(iy, ix, iz), confocal), voxels)
    moved = _peak(spec, _field(_target(iy - 1, ix + 2, iz), confocal), voxels)
    shift = tuple(int(b - a) for a, b in zip(first, moved, strict=True))
    assert shift == (0, -1, 2), (
        f"{spec.qualified_name}: moving the point by (z, y, x) = (0, -1, +2) voxels moved "
        f"the peak by {shift} (confocal={confocal})")


@requires(Capability.PLANE_VOXELS, any_of=GEOMETRIES)
def check_imager_rejects_voxels_behind_wall(spec: PluginSpec, confocal: bool) -> None:
    """Voxels at (z = 0) or behind (z < 0) the wall give a one-line DataError."""
    field = _field(_target(*TARGET_INDEX), confocal)
    wall = fixtures.rect_wall_grid(SHAPE, SPACING)
    for depth in (0.0, -0.3):
        voxels = fixtures.aligned_voxels(wall, [0.5, depth])
        one_line_error(spec, f"voxels at z = {depth} (the wall is z = 0, the hidden scene z > 0)",
                       partial(spec.create(dict(spec.test_config)).reconstruct, field, voxels),
                       DataError)


@requires(Capability.PLANE_VOXELS, any_of=GEOMETRIES)
def check_imager_output_shapes(spec: PluginSpec, confocal: bool) -> None:
    """A plane gives (Y, X), a stack (Z, Y, X); intensities are real, finite and >= 0."""
    field = _field(_target(*TARGET_INDEX), confocal)
    stack = fixtures.aligned_voxels(fixtures.rect_wall_grid(SHAPE, SPACING), [0.5, 0.6])
    imager = spec.create(dict(spec.test_config))
    for voxels in (stack[0], stack):
        out = imager.reconstruct(field, voxels).intensity
        assert out.shape == voxels.shape[:-1], f"shape {out.shape} for voxels {voxels.shape}"
        assert not np.iscomplexobj(out) and np.all(np.isfinite(out)) and out.min() >= 0, (
            f"{spec.qualified_name}: intensity must be real, finite and >= 0")


@requires(Capability.POINT_VOXELS, Capability.RSD, each=GEOMETRIES)
def check_imager_point_voxels(spec: PluginSpec, confocal: bool) -> None:
    """A voxel list (N, 3): 60 random points around the point scatterer and the point
    itself give intensities (N,) that correlate with the reference RSD (>= 0.99) and
    peak at the point (with and without device legs in the field's phase)."""
    shape = (8, 10)
    wall = fixtures.rect_wall_grid(shape, SPACING)
    target = (float(wall[3, 6, 0]), float(wall[3, 6, 1]), 0.6)
    rng = np.random.default_rng(7)
    voxels = np.concatenate([np.asarray([target]),
                             np.asarray(target) + rng.uniform(-0.2, 0.2, (60, 3))])
    for legs in (False, True):
        field = _field(target, confocal, legs, shape=shape, n_frequencies=5)
        image = np.asarray(spec.create(dict(spec.test_config)).reconstruct(field, voxels)
                           .intensity)
        where = f"{spec.qualified_name} (confocal={confocal}, device legs={legs})"
        assert image.shape == (voxels.shape[0],), (
            f"{where}: intensity {image.shape} for a voxel list {voxels.shape}")
        corr = reference.normalised_correlation(image, reference.naive_rsd(field, voxels))
        assert corr >= 0.99, f"{where}: correlation with the reference RSD is {corr:.4f}"
        assert int(np.argmax(image)) == 0, (
            f"{where}: the brightest voxel is {voxels[int(np.argmax(image))]}, not the point "
            f"at {target}")


@requires(Capability.PROGRESS, any_of=GEOMETRIES)
def check_imager_reports_progress(spec: PluginSpec, confocal: bool) -> None:
    """``on_progress(done, total)`` is called with one total, 0 < done <= total, done never
    decreasing and the last call done == total; the image equals the one made without it."""
    field = _field(_target(*TARGET_INDEX), confocal)
    voxels = fixtures.aligned_voxels(fixtures.rect_wall_grid(SHAPE, SPACING), DEPTHS)
    imager = spec.create(dict(spec.test_config))
    calls: list[tuple[int, int]] = []
    image = imager.reconstruct(field, voxels,
                               on_progress=lambda done, total: calls.append((done, total)))
    name = spec.qualified_name
    assert calls, f"{name}: on_progress was never called"
    totals = {total for _, total in calls}
    done = [d for d, _ in calls]
    assert len(totals) == 1 and min(totals) >= 1, f"{name}: totals {sorted(totals)}; expected one"
    assert all(0 < d <= calls[0][1] for d in done) and done == sorted(done), (
        f"{name}: done values {done} must rise within 1..{calls[0][1]}")
    assert done[-1] == calls[0][1], f"{name}: the last call {calls[-1]} must have done == total"
    plain = imager.reconstruct(field, voxels).intensity
    np.testing.assert_array_equal(image.intensity, plain,
                                  err_msg=f"{name}: on_progress changed the image")


IMAGER_CHECKS = (
    check_imager_focuses_point,
    check_imager_resolves_two_points,
    check_imager_matches_reference,
    check_imager_translation,
    check_imager_rejects_voxels_behind_wall,
    check_imager_output_shapes,
    check_imager_point_voxels,
    check_imager_reports_progress,
)

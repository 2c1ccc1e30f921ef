"""fold_spectra: a confocal stack's kernel spectra, one per orbit of the padded lattice,
against the stack itself (numpy only)."""

from __future__ import annotations

import numpy as np
import pytest

from nlosfw.capture import CaptureGeometry, CaptureKind
from nlosfw.image import grid_layout
from nlosfw.model.hybrid import fold_spectra, plane_stack
from nlosfw.model.physics import (
    OperatorOptions,
    SceneOperator,
    VoxelLattice,
    training_grid,
    voxel_lattice,
)
from nlosfw.testing import fixtures
from nlosfw.transform import PhasorField

DEVICE = np.array([-0.6, 0.1, 0.3])
FREQUENCIES = np.linspace(3.0, 6.0, 7)


def _geometry(confocal: bool) -> CaptureGeometry:
    if confocal:
        return CaptureGeometry(kind=CaptureKind.CONFOCAL, laser_xyz=DEVICE, sensor_xyz=DEVICE)
    return CaptureGeometry(kind=CaptureKind.SINGLE_SPOT, laser_point=np.array([0.07, 0, 0]),
                           laser_xyz=DEVICE, sensor_xyz=DEVICE)


def centred_stack(confocal: bool = True, shape: tuple[int, int] = (32, 32)):
    """Every 4th point of a wall of ``shape`` points 1/32 m apart, and the model's own
    lattice for them (voxels 1/32 m apart around the kept points): the kernel's samples
    lie symmetrically about its centre."""
    wall = fixtures.rect_wall_grid(shape, 1 / 32)
    kept = PhasorField(values=np.zeros((FREQUENCIES.size, shape[0] // 4, shape[1] // 4),
                                       complex),
                       frequencies=FREQUENCIES, wall_xyz=wall[1::4, 1::4],
                       geometry=_geometry(confocal), metadata={})
    lattice = voxel_lattice(training_grid(kept, "test"), 1 / 32, np.array([0.4, 0.5, 0.6]))
    return plane_stack(SceneOperator(lattice, grid_layout(wall[1::4, 1::4]), kept.geometry,
                                     FREQUENCIES, OperatorOptions(dtype=np.complex64,
                                                                  workers=1)))


@pytest.mark.parametrize("shape, orbits, most", [((32, 32), 528, 8), ((32, 24), 736, 4)],
                         ids=["square", "oblong"])
def test_every_point_is_its_orbits_spectrum_times_its_phase(shape, orbits, most):
    """Square padded lattice (63 x 63): 32 x 33 / 2 = 528 orbits of up to 8 points (mirror
    in each axis, swap the axes); oblong (63 x 45): 32 x 23 = 736 orbits of up to 4. Each
    point sits in exactly one orbit, and phase x its orbit's spectrum is its own spectrum
    (1e-5 of each plane and frequency's peak)."""
    stack = centred_stack(shape=shape)
    folded = fold_spectra(stack)
    assert folded is not None
    n_planes, n_f, ly, lx = stack.spectra.shape
    assert (ly, lx) == ((63, 63) if shape == (32, 32) else (63, 45))
    assert folded.spectra.shape == (orbits, n_f, n_planes)
    assert folded.members.shape == (orbits, most)
    real = np.sort(folded.members[folded.members < ly * lx])
    np.testing.assert_array_equal(real, np.arange(ly * lx))          # each point once
    np.testing.assert_array_equal(folded.members.reshape(-1)[folded.slots], np.arange(ly * lx))
    orbit = folded.slots // most
    rebuilt = folded.phase[:, None, None] * folded.spectra[orbit]     # (Ly Lx, F, Z)
    want = stack.spectra.transpose(2, 3, 1, 0).reshape(ly * lx, n_f, n_planes)
    peak = np.abs(want).max(axis=0)
    assert np.all(np.abs(rebuilt - want) <= 1e-5 * peak)


def test_stacks_without_the_symmetry_are_not_folded():
    """A single-spot stack (laser legs), and a confocal one whose wall grid is not centred
    on the voxels (the kernel's samples lie off its centre): nothing to fold."""
    assert fold_spectra(centred_stack(confocal=False)) is None
    wall = grid_layout(fixtures.rect_wall_grid((7, 6), 0.06, center=(0.02, -0.01)))
    lattice = VoxelLattice(np.array([0.4, 0.47]), (-0.23, -0.31), (0.06, 0.06), (9, 11))
    stack = plane_stack(SceneOperator(lattice, wall, _geometry(True), FREQUENCIES,
                                      OperatorOptions(dtype=np.complex64, workers=1)))
    assert fold_spectra(stack) is None

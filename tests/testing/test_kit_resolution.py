"""The kit's resolution check fails an imager that does not migrate the field."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from nlosfw.image.reconstruction import Reconstruction
from nlosfw.testing.checks_imager import check_imager_resolves_two_points


class NoMigration:
    """Images each voxel as the field's energy at the wall sample in front of it."""

    def reconstruct(self, field, voxels, on_progress=None):
        energy = (np.abs(field.values) ** 2).sum(axis=0)               # (Y, X)
        return Reconstruction(intensity=np.broadcast_to(energy, voxels.shape[:-1]).copy(),
                              voxels=voxels, metadata={})


@pytest.mark.parametrize("confocal", [False, True])
def test_an_imager_without_migration_fails_the_resolution_check(confocal):
    spec = SimpleNamespace(qualified_name="imager:no_migration", test_config={},
                           create=lambda options: NoMigration())
    with pytest.raises(AssertionError, match="not resolved"):
        check_imager_resolves_two_points(spec, confocal)

"""Phasor-field backprojection written out plainly: any Imager has this shape."""

import numpy as np

from nlosfw import DataError, Imager, PhasorField, Reconstruction
from nlosfw.image import ProgressCallback, laser_phase, path_multiplier, phasor_steps, wall_field
from nlosfw_example_imager.hooks import BackprojectionConfig


class BackprojectionImager(Imager[BackprojectionConfig]):
    """Each voxel v sums every wall sample's phasor, delayed by the path back to v:

        I(v) = | sum_f w_f L_f(v) sum_s P'_f(s) exp(2 pi i f m |v - s|) / |v - s| |^2

    with nlosfw's conventions (nlosfw.image's RSD kernel): m = 2 for confocal scans and
    1 for a single laser spot, whose leg L_f(v) undoes; P' has the device legs undone;
    w_f are the field's spectral weights. Any voxels: planes or a list of points.
    O(voxels x wall samples x frequencies): small volumes only, so it reports progress
    after each block of voxels (the run shows it as a progress bar).
    """

    config_class = BackprojectionConfig

    def reconstruct(self, field: PhasorField, voxels: np.ndarray,
                    on_progress: ProgressCallback | None = None) -> Reconstruction:
        points = np.asarray(voxels, dtype=float)
        if points.shape[-1:] != (3,) or not np.all(np.isfinite(points)):
            raise DataError(f"voxels: need finite (x, y, z) points, got shape {points.shape}")
        if points[..., 2].min() <= 0:
            raise DataError(f"voxels: z must be > 0 (in front of the wall at z = 0), got "
                            f"min z = {points[..., 2].min():.6g} m")
        multiplier = path_multiplier(field.geometry)       # DataError for other geometries
        values = wall_field(field).reshape(field.n_frequencies, -1)            # (F, S)
        wall = field.wall_xyz.reshape(-1, 3)
        flat = points.reshape(-1, 3)
        intensity = np.empty(flat.shape[0])
        for start in range(0, flat.shape[0], self.config.block):
            block = flat[start:start + self.config.block]
            r = np.linalg.norm(block[:, None, :] - wall[None, :, :], axis=-1)  # (n, S)
            legs = laser_phase(field.frequencies, block, field.geometry)      # (F, n) or None
            total = np.zeros(block.shape[0], dtype=np.complex128)
            # exp(2 pi i f m r) / r for one frequency after another, (n, S) each; the sum
            # over wall samples by einsum (a BLAS matrix-vector product crawls on busy cores)
            for i, kern in phasor_steps(field.frequencies, multiplier * r, scale=1 / r):
                u = np.einsum("vs,s->v", kern, values[i])                      # (n,)
                total += field.effective_weights[i] * (u if legs is None else u * legs[i])
            intensity[start:start + block.shape[0]] = np.abs(total) ** 2
            if on_progress is not None:
                on_progress(start + block.shape[0], flat.shape[0])   # (done, total)
        return Reconstruction(intensity=intensity.reshape(points.shape[:-1]), voxels=points,
                              metadata={"imager": "example_backprojection"})

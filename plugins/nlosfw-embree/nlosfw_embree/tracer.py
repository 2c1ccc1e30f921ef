"""Occlusion queries against the hidden triangles with Embree (through embreex).

embreex traces one ray at a time in a C loop that releases the GIL, so several
Python threads can query one committed scene at once. Rays start at
``tnear = 0``: callers move their origins off the surface they leave.
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh as EmbreeTriangles

from nlosfw.simulate import TriangleMesh

#: Value of ``occluded`` for a ray that reaches its end unobstructed (embreex convention).
FREE = -1


class OcclusionTracer:
    """A committed Embree scene of a :class:`~nlosfw.simulate.geometry.TriangleMesh`."""

    def __init__(self, mesh: TriangleMesh) -> None:
        self.n_faces = mesh.n_faces
        self._scene = None
        if mesh.n_faces:
            scene = rtcore_scene.EmbreeScene(robust=True)
            EmbreeTriangles(scene, np.ascontiguousarray(mesh.vertices, dtype=np.float32),
                            np.ascontiguousarray(mesh.faces, dtype=np.int32))
            # embreex commits on the first query; do it now, before threads share the scene
            one = np.zeros((1, 3), np.float32)
            scene.run(one, np.array([[0.0, 0.0, -1.0]], np.float32), query="OCCLUDED")
            self._scene = scene

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 tfar: np.ndarray) -> np.ndarray:
        """int32 per ray: 0 if a triangle lies within ``t in [0, tfar]``, else :data:`FREE` (-1).

        ``origins`` and ``directions`` are float32 (n, 3) (directions need not be
        unit vectors; ``tfar`` is in units of their length), ``tfar`` float32 (n,).
        """
        if self._scene is None:
            return np.full(origins.shape[0], FREE, np.int32)
        return self._scene.run(origins, directions, dists=tfar, query="OCCLUDED")

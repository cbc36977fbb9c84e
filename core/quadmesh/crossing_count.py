# SPDX-License-Identifier: LGPL-2.1-or-later
"""Self-crossings of the limit surfaces of cages that differ from one cage in vertex positions
only, counted again only where the limit surface moved.

The repairs of the budget ladder of :mod:`core.quadmesh.decimation.paired_decimation` judge every
trial cage by the self-crossing triangle pairs of its level-2 limit surface (as
``core.subdivision.limit_crossings.count_limit_self_intersections``). Their trials move a few
vertices of one cage, which moves a part of the limit mesh's triangles; the pairs of two unmoved
triangles are those of the first cage. So the limit mesh is built once as a matrix of the base
vertices, and each count tests only the pairs with a moved triangle
(``core.self_intersection.find_self_intersections(..., among=moved)``), which is faster than a whole
search when only a few vertices moved. A cage's crease tags (``PolyMesh.creases``) are part of its
limit surface here as everywhere (the limit mesh is built with the crease rules and masks).
"""
import numpy as np

from core.geometry import triangulate
from core.self_intersection import find_self_intersections
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices

LEVELS = 2
"""Subdivision level of the limit mesh checked (as
``core.quadmesh.decimation.paired_decimation``)."""


class LimitCrossingCount:
    """Self-crossing triangle pairs of the level-:data:`LEVELS` limit mesh of cages.

    Parameters
    ----------
    mesh : PolyMesh closed 2-manifold cage, the reference.

    Attributes
    ----------
    crossings : int, the pairs of ``mesh`` itself.
    """

    def __init__(self, mesh):
        hierarchy = build_hierarchy(mesh, LEVELS)
        fine = hierarchy.meshes[LEVELS]
        limit, _, _ = limit_matrices(fine)
        self._mesh = mesh
        self._operator = (limit @ hierarchy.composite(LEVELS - 1)).tocsr()
        self._triangles = triangulate(fine.face_vertices, fine.face_offsets)
        self._points = self._operator @ mesh.vertices
        self._pairs = find_self_intersections(self._points, self._triangles)
        self.crossings = int(len(self._pairs))

    def __call__(self, mesh):
        """Self-crossing pairs (an int) of ``mesh``'s limit mesh: only those with a moved
        triangle are tested when ``mesh`` has the reference's faces, all otherwise."""
        if not (np.array_equal(mesh.face_offsets, self._mesh.face_offsets)
                and np.array_equal(mesh.face_vertices, self._mesh.face_vertices)):
            return LimitCrossingCount(mesh).crossings
        points = self._operator @ mesh.vertices
        moved = np.any(points != self._points, axis=1)[self._triangles].any(axis=1)
        kept = ~moved[self._pairs].any(axis=1)
        return int(kept.sum()) + len(find_self_intersections(points, self._triangles,
                                                             among=moved))

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
search when only a few vertices moved. A trial with other faces (a split quad) gets a limit mesh
of its own, kept for the trials with its faces that follow (the moves tried on a split cage
once the split is kept). A cage's crease tags (``PolyMesh.creases``) are part of its
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
        self._other = None  # the count of the last cage with other faces

    def __call__(self, mesh):
        """Self-crossing pairs (an int) of ``mesh``'s limit mesh: only those with a moved
        triangle are tested when ``mesh`` has the reference's faces, all otherwise (those
        with a moved triangle only, where it has the faces of the last cage with other faces
        counted and its limit mesh spans the same box, so that the contact tolerance of the
        search is the same as in a full count of it)."""
        if not self._has_faces(mesh):
            other = self._other
            if other is not None and other._has_faces(mesh):
                return other._count_moved(mesh, same_box=True)
            self._other = LimitCrossingCount(mesh)
            return self._other.crossings
        return self._count_moved(mesh)

    def _has_faces(self, mesh):
        """True when ``mesh`` has the reference's faces."""
        return (np.array_equal(mesh.face_offsets, self._mesh.face_offsets)
                and np.array_equal(mesh.face_vertices, self._mesh.face_vertices))

    def _count_moved(self, mesh, same_box=False):
        """The pairs of ``mesh`` (the reference's faces), testing only moved triangles; with
        ``same_box``, all of them where the limit mesh's bounding box moved."""
        points = self._operator @ mesh.vertices
        if same_box and not (np.array_equal(points.min(axis=0), self._points.min(axis=0))
                             and np.array_equal(points.max(axis=0), self._points.max(axis=0))):
            return len(find_self_intersections(points, self._triangles))
        moved = np.any(points != self._points, axis=1)[self._triangles].any(axis=1)
        kept = ~moved[self._pairs].any(axis=1)
        return int(kept.sum()) + len(find_self_intersections(points, self._triangles,
                                                             among=moved))

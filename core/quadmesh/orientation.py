# SPDX-License-Identifier: LGPL-2.1-or-later
"""Inverted base faces: the limit surface facing away from the target.

A base face is inverted when the Catmull-Clark limit-surface normal at its centre points more
than 90 degrees away from the target's normal at the target point closest to that limit point.
"""
import numpy as np

from core.target_surface import TargetSurface
from core.subdivision.catmull_clark import subdivide
from core.subdivision.limit import limit_matrices


def face_centre_limit(base):
    """Limit position and unit outward limit normal at the centre of every base face.

    base : PolyMesh, closed 2-manifold (any face sizes). Returns ``(points, normals)``, both
    (f, 3) float64: one subdivision step turns every face centre into a vertex (its face
    point), whose exact limit position and normal are evaluated.
    """
    fine, _ = subdivide(base)
    L, Tu, Tv = limit_matrices(fine)
    centre = len(base.vertices) + np.arange(base.n_faces)
    points = (L @ fine.vertices)[centre]
    normal = np.cross((Tu @ fine.vertices)[centre], (Tv @ fine.vertices)[centre])
    return points, normal / np.linalg.norm(normal, axis=1, keepdims=True)


def inverted_faces(base, target_vertices, target_faces, surface=None):
    """(f,) bool base faces whose limit normal is more than 90 degrees from the target's.

    Parameters
    ----------
    base : PolyMesh base mesh; target_vertices : (n, 3) float64; target_faces : (m, 3) int64.
    surface : TargetSurface of that target already built, or None (built here).
    """
    points, normals = face_centre_limit(base)
    if surface is None:
        surface = TargetSurface(target_vertices, target_faces)
    target_normal = surface.closest(points).normal
    return np.einsum("fk,fk->f", normals, target_normal) < 0.0

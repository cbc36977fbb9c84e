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
    step, L, Tu, Tv = _centre_operators(base)
    fine = step @ np.asarray(base.vertices, dtype=np.float64)
    normal = np.cross(Tu @ fine, Tv @ fine)
    return L @ fine, normal / np.linalg.norm(normal, axis=1, keepdims=True)


_LAST_OPERATORS = []
"""The faces, creases and :func:`_centre_operators` of the last cage asked about."""


def _centre_operators(base):
    """``(S, L, Tu, Tv)``: the subdivision step of ``base`` (sparse, (n_fine, n)) and the rows
    of the fine mesh's limit masks (:func:`core.subdivision.limit.limit_matrices`) at the
    face points, (f, n_fine) each.

    They depend on the faces and creases only; the last cage's are kept, since the repairs
    judge many cages with the faces of one and vertices moved. The rows give the products
    of the whole masks bit for bit (a sparse row's sum does not depend on the other rows).
    """
    creases = None if base.creases is None else np.asarray(base.creases)
    if _LAST_OPERATORS:
        face_vertices, face_offsets, kept_creases, operators = _LAST_OPERATORS[0]
        if (np.array_equal(face_vertices, base.face_vertices)
                and np.array_equal(face_offsets, base.face_offsets)
                and (creases is None) == (kept_creases is None)
                and (creases is None or np.array_equal(creases, kept_creases))):
            return operators
    fine, step = subdivide(base)
    centre = len(base.vertices) + np.arange(base.n_faces)
    operators = (step, *(matrix[centre] for matrix in limit_matrices(fine)))
    _LAST_OPERATORS[:] = [(np.array(base.face_vertices), np.array(base.face_offsets),
                           None if creases is None else creases.copy(), operators)]
    return operators


def face_centre_operators(base):
    """Limit position and limit tangents at every face centre as linear maps of the base
    vertices: ``(L, Tu, Tv)``, sparse (f, n) each (:func:`face_centre_limit` multiplies them
    by the vertices; the normal is ``Tu v x Tv v``)."""
    step, L, Tu, Tv = _centre_operators(base)
    return (L @ step).tocsr(), (Tu @ step).tocsr(), (Tv @ step).tocsr()


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

# SPDX-License-Identifier: LGPL-2.1-or-later
"""The target's sharp feature lines, and the crease networks of cages.

A machined part's sharp steps (counterbores, pockets) are rounded by the smooth Catmull-Clark
limit over a face's length, which makes the limit of a coarse cage fold there
(docs/DESIGN.md). Cage edges along them tagged as infinitely sharp creases
(``PolyMesh.creases``, :mod:`core.subdivision.catmull_clark`) keep the step. The target's
feature lines are its edges whose dihedral angle exceeds :data:`CREASE_ANGLE`
(:func:`feature_edges`); the feature-preserving decimation
(:mod:`core.quadmesh.decimation.feature_decimation`) keeps them as chains of edges of the cage.

Chains of crease edges that end inside a face region (at a dart: a vertex with one crease
edge) are cut back until every crease vertex has two or more crease edges
(:func:`closed_network`): a machined part's feature lines are closed or end at corners, and
a chain ends inside only where the cage lost part of its line.

Tagging only the edges of a QSlim decimation that happen to lie along the feature lines is
not enough: QSlim crosses many steps diagonally with cage edges, which cannot be creased, and
the limit surface then crosses itself there. The feature-preserving decimation
(:mod:`core.quadmesh.decimation.feature_decimation`) keeps every line a chain of cage edges.
"""
import numpy as np

from core.mesh_topology import edge_faces

CREASE_ANGLE = 60.0
"""Degrees: the smallest dihedral angle of a target feature edge."""


def feature_edges(vertices, faces, angle=CREASE_ANGLE):
    """(k, 2) int64 edges of a closed triangle mesh whose dihedral angle exceeds ``angle``.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed 2-manifold, outward.
    angle : float, degrees: the angle between the two unit face normals.
    """
    from core.geometry import unit_face_normals

    edges, pairs = edge_faces(faces)
    normal = unit_face_normals(vertices, faces)
    cosine = np.einsum("ij,ij->i", normal[pairs[:, 0]], normal[pairs[:, 1]])
    return edges[cosine < np.cos(np.radians(angle))]


def closed_network(creases, n_vertices):
    """The crease edges left after cutting back every chain that ends at a dart.

    Parameters
    ----------
    creases : (c, 2) int64 vertex pairs; n_vertices : int.

    Returns
    -------
    None when none is left, else (c', 2) int64, a subset of ``creases`` in which every
    vertex has zero or at least two crease edges.
    """
    while len(creases):
        count = np.bincount(creases.reshape(-1), minlength=n_vertices)
        dangling = (count[creases] == 1).any(axis=1)
        if not dangling.any():
            return creases
        creases = creases[~dangling]
    return None

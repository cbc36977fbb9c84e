# SPDX-License-Identifier: LGPL-2.1-or-later
"""Unshrink the limit surface of a cage at its inverted faces.

A paired-decimation cage has its vertices on the target, and the Catmull-Clark limit surface
lies inside such a cage, pulled in by about the size of its faces. Where a feature is thinner
than that, the limit surface is pulled past the feature's middle and its nearest target point
lies on the far side (:func:`core.quadmesh.orientation.inverted_faces` counts the face as
inverted). A plate's thin rim, the thin wall round a pin's bore or a thin SIMP strut each
have their limit surface pulled inside past the wall's middle this way. The cage faces there
face the right way, their limit does not reach the target.

The repair asks the limit surface to pass through the cage's original vertices (which lie on
the target, on the right side of the feature): Jacobi steps ``v += p - L(v)`` on the vertices
of the inverted faces (``p`` a vertex's on-target position, ``L(v)`` its limit position), the
set growing with the faces still inverted after each step. An exact interpolation of a thin
feature asks for large moves, so each step is cut to :data:`STEP_SHARE` and the whole move to
:data:`MOVE_SHARE` of the vertex's shortest edge. The steps are judged on the limit surface:
the cage kept is the one with the fewest inverted faces among those whose limit surface has
no more self-crossings than the original (the original itself if none has fewer).
"""
from dataclasses import replace

import numpy as np

from core.geometry import shortest_edges_at
from core.mesh_topology import next_corners
from core.quadmesh.orientation import inverted_faces
from core.subdivision.catmull_clark import subdivide
from core.subdivision.limit import limit_matrices

STEPS = 8
"""Jacobi steps tried: the inverted faces (and crossings) usually fall over the first
five or six steps."""
STEP_SHARE = 0.5
"""Largest move of one step, as a share of the vertex's shortest edge (full steps overshoot:
fewer inverted faces, but new crossings of the limit surface)."""
MOVE_SHARE = 2.0
"""Largest move in all, as a share of the vertex's shortest edge (at 1 a thin pin eye keeps
most of its inverted faces; unbounded, vertices move many edge lengths)."""


def shortest_edges(mesh):
    """(n,) float64 length of the shortest edge at every vertex of ``mesh`` (model units)."""
    corners = mesh.face_vertices
    return shortest_edges_at(mesh.vertices,
                             np.stack([corners, corners[next_corners(mesh.face_offsets)]], axis=1))


def vertex_limit_positions(mesh):
    """(n, 3) float64 Catmull-Clark limit position of every vertex of ``mesh`` (any faces:
    one subdivision step keeps the vertices first and makes all faces quads)."""
    fine, _ = subdivide(mesh)
    limit, _, _ = limit_matrices(fine)
    return (limit @ fine.vertices)[:len(mesh.vertices)]


def unshrink_inverted(mesh, surface, crossings, inverted, count_crossings):
    """The cage with fewer inverted faces and no more limit crossings, moved as the module says.

    Parameters
    ----------
    mesh : PolyMesh closed 2-manifold cage, vertices on the target.
    surface : TargetSurface of the target.
    crossings, inverted : int, the limit flaws of ``mesh`` (self-crossing triangle pairs of
        its level-2 limit surface, inverted faces).
    count_crossings : callable PolyMesh -> int, the self-crossing pairs of a cage's limit
        surface (as ``crossings`` was counted).

    Returns
    -------
    mesh : PolyMesh, the same faces; ``mesh`` itself when no step helped.
    crossings, inverted : int, its limit flaws.
    moved : int, vertices moved off the target.
    """
    if not inverted:
        return mesh, crossings, inverted, 0
    anchors = mesh.vertices
    reach = shortest_edges(mesh)
    face_of_corner = np.repeat(np.arange(mesh.n_faces), mesh.face_sizes)
    moving = np.zeros(len(anchors), dtype=bool)
    best = (mesh, crossings, inverted, 0)
    current = mesh
    flipped = inverted_faces(current, surface.vertices, surface.faces, surface)
    for _ in range(STEPS):
        moving[mesh.face_vertices[flipped[face_of_corner]]] = True
        step = anchors - vertex_limit_positions(current)
        step *= _cut(step, STEP_SHARE * reach)
        vertices = current.vertices.copy()
        vertices[moving] += step[moving]
        move = vertices - anchors
        vertices = anchors + move * _cut(move, MOVE_SHARE * reach)
        current = replace(mesh, vertices=vertices)
        flipped = inverted_faces(current, surface.vertices, surface.faces, surface)
        count = int(flipped.sum())
        if count < best[2]:
            current_crossings = count_crossings(current)
            if current_crossings <= crossings:
                best = (current, current_crossings, count, int(moving.sum()))
        if not count:
            break
    return best


def _cut(vectors, largest):
    """(k, 1) float64 factors that shorten each of ``vectors`` (k, 3) to at most ``largest``
    (k,)."""
    length = np.linalg.norm(vectors, axis=1)
    return np.minimum(1.0, largest / np.maximum(length, 1e-300))[:, None]

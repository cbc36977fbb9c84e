# SPDX-License-Identifier: LGPL-2.1-or-later
"""Which cage edges are sharp creases: those that follow a sharp feature line of the target.

A machined part's sharp steps (counterbores, pockets) are rounded by the smooth Catmull-Clark
limit over a face's length, which makes the limit of a coarse cage fold there (issue 8,
docs/DESIGN.md). Tagging the cage edges on those steps as infinitely sharp creases
(``PolyMesh.creases``, :mod:`core.subdivision.catmull_clark`) keeps the step. A cage edge is
a crease when both hold:

1. it follows the target's feature lines: every one of :data:`EDGE_SAMPLES` points along it
   lies within :data:`FEATURE_REACH` of its length of a target edge whose dihedral angle
   (between the normals of its two triangles) exceeds :data:`CREASE_ANGLE`;
2. the target bends there as much on the cage's scale: the mean target normals under the
   two cage faces next to it (at the closest points of :data:`SIDE_SAMPLES` points a quarter
   of the way from the edge to each face's centroid) differ by more than
   :data:`CREASE_ANGLE`.

Chains of crease edges that end inside a face region (at a dart: a vertex with one crease
edge) are then cut back until every crease vertex has two or more crease edges
(:func:`closed_network`): a machined part's feature lines are closed or end at corners, and
a chain ends inside only where the cage missed part of its line. On the dev meshes the cut
removed about a third of the crease edges and left fewer crossings of the limit surface
(``featuretype`` at budgets of 300 to 900 faces: 97-512 crossing pairs instead of 259-799;
``octagonal_pocket``: 3-256 instead of 16-197; noisy from budget to budget).

Smooth targets (SIMP results) have no feature lines of such angles under their cage edges,
so their cages get no creases.
"""
import numpy as np
from scipy.spatial import cKDTree

from core.mesh_topology import edge_faces
from core.subdivision.catmull_clark import mesh_topology

CREASE_ANGLE = 60.0
"""Degrees: the smallest dihedral angle of a target feature edge, and the smallest angle
between the target's mean normals on the two sides of a crease edge."""
FEATURE_REACH = 0.15
"""Largest distance of a crease edge's points from the feature lines, as a fraction of the
edge's length: a straight cage edge along a curved feature line is a chord of it (a chord
over an eighth of a circle lies 0.1 of its length off the arc)."""
EDGE_SAMPLES = 9
"""Points tested along each cage edge (both ends included)."""
SIDE_SAMPLES = 3
"""Points whose target normals are averaged on each side of a cage edge."""


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


def crease_edges(mesh, surface, angle=CREASE_ANGLE):
    """Cage edges on the target's sharp feature lines (module docstring).

    Parameters
    ----------
    mesh : PolyMesh closed 2-manifold cage, vertices on (or near) the target.
    surface : core.target_surface.TargetSurface of the target.
    angle : float, degrees (:data:`CREASE_ANGLE`).

    Returns
    -------
    None when no edge is a crease, else (c, 2) int64 sorted vertex pairs, a closed network
    (:func:`closed_network`).
    """
    features = feature_edges(surface.vertices, surface.faces, angle)
    if not len(features):
        return None
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    X = mesh.vertices
    ends = X[topo.edges]
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    spacing = 0.25 * FEATURE_REACH * float(length.min())
    tree = cKDTree(_segment_points(surface.vertices[features], spacing))
    t = np.linspace(0.0, 1.0, EDGE_SAMPLES)
    along = ends[:, :1] + t[None, :, None] * (ends[:, 1:] - ends[:, :1])
    distance, _ = tree.query(along.reshape(-1, 3))
    near = (distance.reshape(len(length), EDGE_SAMPLES)
            <= FEATURE_REACH * length[:, None] + spacing).all(axis=1)
    candidates = np.flatnonzero(near)
    if not len(candidates):
        return None
    sides = [_side_normal(mesh, topo, surface, candidates, side) for side in (0, 1)]
    bent = np.einsum("ij,ij->i", *sides) < np.cos(np.radians(angle))
    return closed_network(topo.edges[candidates[bent]], len(X))


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


def _segment_points(segments, spacing):
    """(p, 3) points along segments ((k, 2, 3)) at most ``spacing`` apart, ends included."""
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    count = np.maximum(np.ceil(length / spacing).astype(np.int64), 1)
    seg = np.repeat(np.arange(len(segments)), count + 1)
    start = np.repeat(np.cumsum(count + 1) - (count + 1), count + 1)
    t = (np.arange(len(seg)) - start) / np.repeat(count, count + 1)
    return segments[seg, 0] + t[:, None] * (segments[seg, 1] - segments[seg, 0])


def _side_normal(mesh, topo, surface, edges, side):
    """(c, 3) unit mean target normal under the face on ``side`` (0 or 1) of cage ``edges``.

    Side 0 is the face of the edge's first half-edge in corner order, side 1 the other.
    """
    corners = np.arange(len(mesh.face_vertices))
    first = np.full(len(topo.edges), -1, dtype=np.int64)
    first[topo.corner_edge[::-1]] = corners[::-1]
    corner = first[edges] if side == 0 else topo.twin[first[edges]]
    face = topo.face_of_corner[corner]
    sizes = np.diff(mesh.face_offsets).astype(np.float64)
    centroid = np.zeros((mesh.n_faces, 3))
    np.add.at(centroid, topo.face_of_corner, mesh.vertices[mesh.face_vertices])
    centroid /= sizes[:, None]
    a = mesh.vertices[mesh.face_vertices[corner]]
    b = mesh.vertices[mesh.face_vertices[topo.next_corner[corner]]]
    t = (np.arange(SIDE_SAMPLES) + 0.5) / SIDE_SAMPLES
    on_edge = a[:, None] + t[None, :, None] * (b - a)[:, None]
    points = on_edge + 0.25 * (centroid[face][:, None] - on_edge)
    near = surface.nearest(points.reshape(-1, 3))
    normal = surface.face_normals[near.face].reshape(len(edges), SIDE_SAMPLES, 3).sum(axis=1)
    return normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)

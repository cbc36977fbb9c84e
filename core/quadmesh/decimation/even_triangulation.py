# SPDX-License-Identifier: LGPL-2.1-or-later
"""Even out a coarse triangulation of the target before its triangles are paired into quads.

QSlim keeps a flat plate with only its rim vertices, so the plate becomes a fan of long
triangles, and near the end of a strong decimation it leaves triangles folded over their
neighbours, facing away from the target. The paired quads inherit
both, and the Catmull-Clark limit surface crosses itself and turns inside out there. This module
repairs the triangulation with the topology-preserving operators of isotropic remeshing (Botsch
& Kobbelt, "A remeshing approach to multiresolution modeling", SGP 2004), keeping QSlim's
feature-aware vertex placement. They act on planar regions only (triangles within
:data:`PLANAR_ANGLE` of coplanar): machined plates are planar, a SIMP iso-surface is not, and
there splits and flips were measured to make the fit of thin struts worse.

1. planar fans are found: edges more than :data:`LONG_EDGE` times the length of an equilateral
   triangle of the mean area, between two coplanar triangles. When there are any, the
   triangulation is decimated further by two triangles per such edge (QSlim again, on the
   small mesh), and then its longest planar edges are split (their midpoints moved onto the
   target) until the count is back: the fans get vertices in the plate's interior;
2. edges are flipped, first to untangle a triangle folded flat over its neighbour (the two
   coplanar but facing opposite ways, one of them away from the target), then across planar
   edges to raise the smallest angles (a Delaunay-like criterion);
3. rounds of those flips alternate with smoothing inside planar regions: a vertex whose
   triangles are all coplanar moves to the mean of its neighbours, which lies in the same
   plane (the shape is kept).

On machined parts and plates this removes most of the crossing triangle pairs and inverted
faces of the paired cages' limit surfaces (``benchmarks/BASEMESH_RESULTS.md``). Tangential
smoothing on the target everywhere is not used: it inverts faces on thin SIMP members.
"""
import numpy as np

from core.geometry import face_cross, unit_face_normals
from core.mesh_topology import unique_edges

LONG_EDGE = 2.0
"""An edge this many times longer than an equilateral triangle's of the mean area is long."""
MAX_SPLIT_SHARE = 0.25
"""At most this share of the triangles is made by splits."""
PLANAR_ROUNDS = 4
"""Rounds of flips and smoothing inside planar regions."""
PLANAR_ANGLE = np.radians(2.0)
"""Two triangles are coplanar when their normals are this close (or this close to opposite).
Machined plates are planar to this; a SIMP result's smoothed iso-surface is not, so it is left
as QSlim made it (where splits and flips were measured to worsen the fit of thin struts)."""
MIN_NORMAL_AGREEMENT = 0.5
"""A triangle faces the target when its normal is within 60 degrees of the target's."""


def even_triangulation(vertices, faces, surface):
    """Split planar fans, then flip edges, of a closed coarse triangulation (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64 vertices near the target (model units).
    faces : (m, 3) int64 closed, outward 2-manifold triangles (QSlim's result).
    surface : TargetSurface: new vertices are placed on it, and triangles are judged facing
        it or not by its normals.

    Returns
    -------
    vertices : (n', 3) float64; faces : (m', 3) int64, the same topology (genus,
    orientation), ``m' <= m`` and ``m - m'`` at most twice the planar long edges not split.
    """
    import igl

    vertices = np.array(vertices, dtype=np.float64)
    faces = np.array(faces, dtype=np.int64)
    wanted = len(faces)
    splits = min(int(_flat_long_edges(vertices, faces).sum()),
                 int(MAX_SPLIT_SHARE * wanted) // 2)
    if splits:
        vertices, faces, _, _ = igl.qslim(vertices, faces, wanted - 2 * splits)
        faces = np.asarray(faces, dtype=np.int64)
        while len(faces) + 1 < wanted:
            vertices, faces, done = _split_longest(vertices, faces, surface,
                                                   (wanted - len(faces)) // 2)
            if not done:
                break
    for _ in range(PLANAR_ROUNDS):
        faces = _flip_pass(vertices, faces, surface)
        vertices = _smooth_planar(vertices, faces)
    return vertices, _flip_pass(vertices, faces, surface)


def even_creased_triangulation(decimation, count, surface):
    """Steps 2 and 3 of :func:`even_triangulation` on a feature-preserving decimation.

    The decimation to ``count`` triangles (a
    :class:`core.quadmesh.decimation.feature_decimation.FeatureDecimation`) gets rounds of flips
    (never of a feature edge) and planar smoothing (never of a vertex on one). Feature edges join
    triangles bent by more than the planar angle on the target, so these flips and moves, inside
    planar regions only, keep the shape and the feature lines. Step 1 (QSlim's second pass, then
    splits) is left out: QSlim would cut across the feature lines, and a feature-preserving
    decimation to fewer triangles before the splits drops line vertices (fewer crease edges, a
    fitted solid farther from the target, and crossings of the limit surface).

    Parameters
    ----------
    decimation : FeatureDecimation; count : int, triangles wanted; surface : TargetSurface.

    Returns
    -------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed, outward, the decimation's
    topology and feature edges; features : (k, 2) int64 sorted vertex pairs, those edges.
    """
    vertices, faces, features = decimation.triangles(count)
    vertices = vertices.copy()
    on_feature = np.zeros(len(vertices), dtype=bool)
    on_feature[features.reshape(-1)] = True
    for _ in range(PLANAR_ROUNDS):
        faces = _flip_pass(vertices, faces, surface, fixed=features)
        vertices = _smooth_planar(vertices, faces, on_feature)
    return vertices, _flip_pass(vertices, faces, surface, fixed=features), features


def _smooth_planar(vertices, faces, fixed=None):
    """Move every vertex inside a planar region to the mean of its neighbours.

    A vertex is inside a planar region when all its triangles are coplanar
    (:data:`PLANAR_ANGLE`) and face the same way; its neighbours then lie in that plane, and
    so does their mean: the shape does not change. A move that would turn one of its
    triangles over (a non-convex neighbourhood) is not made, nor one of a ``fixed`` vertex
    ((n,) bool or None).
    """
    normals = unit_face_normals(vertices, faces)
    n = len(vertices)
    corner_face = np.repeat(np.arange(len(faces)), 3)
    corner_vertex = faces.reshape(-1)
    summed = np.zeros((n, 3))
    np.add.at(summed, corner_vertex, normals[corner_face])
    count = np.bincount(corner_vertex, minlength=n).astype(float)
    mean_normal = summed / np.maximum(count, 1.0)[:, None]
    agreement = np.full(n, np.inf)
    np.minimum.at(agreement, corner_vertex,
                  np.einsum("ij,ij->i", normals[corner_face], mean_normal[corner_vertex]))
    planar = agreement > np.cos(PLANAR_ANGLE)
    if fixed is not None:
        planar &= ~fixed
    edges, _ = unique_edges(faces)
    ends = edges.reshape(-1)
    others = edges[:, ::-1].reshape(-1)
    total = np.zeros((n, 3))
    np.add.at(total, ends, vertices[others])
    degree = np.bincount(ends, minlength=n).astype(float)
    moved = vertices.copy()
    moved[planar] = total[planar] / degree[planar, None]
    moving = planar.copy()
    for _ in range(10):
        trial = np.where(moving[:, None], moved, vertices)
        turned = np.einsum("ij,ij->i", face_cross(trial, faces), normals) <= 0
        if not turned.any():
            return trial
        moving[faces[turned].reshape(-1)] = False
    return vertices


def _flat_long_edges(vertices, faces):
    """(e,) bool edges (of :func:`_edge_halfedges`) longer than :data:`LONG_EDGE` times the
    edge of an equilateral triangle of the mean area, between coplanar triangles."""
    edges, halfedges = _edge_halfedges(faces)
    cross = face_cross(vertices, faces)
    mean_area = 0.5 * np.linalg.norm(cross, axis=1).mean()
    long = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1) \
        > LONG_EDGE * np.sqrt(4.0 * mean_area / np.sqrt(3.0))
    normals = unit_face_normals(vertices, faces)
    flat = np.einsum("ij,ij->i", normals[halfedges[:, 0] // 3], normals[halfedges[:, 1] // 3]) \
        > np.cos(PLANAR_ANGLE)
    return long & flat


def _is_fixed(edges, fixed, n):
    """(e,) bool: which of the sorted vertex pairs ``edges`` are among ``fixed`` ((k, 2) int64
    vertex pairs in any order, or None: none)."""
    if fixed is None or not len(fixed):
        return np.zeros(len(edges), dtype=bool)
    codes = np.minimum(fixed[:, 0], fixed[:, 1]) * n + np.maximum(fixed[:, 0], fixed[:, 1])
    return np.isin(edges[:, 0] * n + edges[:, 1], codes)


def _edge_halfedges(faces):
    """Undirected edges with their two half-edges.

    Returns
    -------
    edges : (e, 2) int64 sorted vertex pairs.
    halfedges : (e, 2) int64 indices ``3 * face + corner`` of the two half-edges of each edge
        (the half-edge from corner ``k`` to ``k + 1``), closed 2-manifold input.
    """
    edges, halfedge_edge = unique_edges(faces)
    order = np.argsort(halfedge_edge, kind="stable")
    return edges, order.reshape(-1, 2)


def _wings(faces, halfedges):
    """For half-edges ``h`` (k,): tail ``a``, head ``b`` and apex ``c`` of their triangles."""
    face, corner = np.divmod(halfedges, 3)
    return (faces[face, corner], faces[face, (corner + 1) % 3], faces[face, (corner + 2) % 3],
            face)


def _disjoint(candidates, faces_of):
    """(k,) bool: greedily keep candidates (indices, in the given order) that share no face.

    candidates : (c,) int64 indices into ``faces_of``, most wanted first.
    faces_of : (k, j) int64 the faces each of the k possible changes touches.
    """
    taken = np.zeros(int(faces_of.max()) + 1 if faces_of.size else 0, dtype=bool)
    keep = np.zeros(len(faces_of), dtype=bool)
    for i, touched in zip(candidates.tolist(), faces_of[candidates].tolist()):
        if not taken[touched].any():
            taken[touched] = True
            keep[i] = True
    return keep


def _split_longest(vertices, faces, surface, most):
    """Split up to ``most`` of the longest planar long edges, no two of one triangle, at their
    midpoints.

    Each split edge ``a``-``b`` between the triangles ``(a, b, c)`` and ``(b, a, d)`` gets a new
    vertex ``m`` at the target point nearest its midpoint, and the two triangles become four.
    Returns ``(vertices, faces, split_any)``.
    """
    edges, halfedges = _edge_halfedges(faces)
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    order = np.argsort(-length, kind="stable")
    order = order[_flat_long_edges(vertices, faces)[order]]
    keep = _disjoint(order, halfedges // 3)
    chosen = order[keep[order]][:most]
    if not len(chosen):
        return vertices, faces, False
    a, b, c, f1 = _wings(faces, halfedges[chosen, 0])
    _, _, d, f2 = _wings(faces, halfedges[chosen, 1])
    midpoint = surface.nearest(0.5 * (vertices[a] + vertices[b])).point
    m = len(vertices) + np.arange(len(chosen))
    faces = faces.copy()
    faces[f1] = np.stack([a, m, c], axis=1)
    faces[f2] = np.stack([b, m, d], axis=1)
    added = np.concatenate([np.stack([m, b, c], axis=1), np.stack([m, a, d], axis=1)])
    return np.vstack([vertices, midpoint]), np.vstack([faces, added]), True


def _min_angles(vertices, triangles):
    """(k,) float64 smallest corner angle (radians) of each triangle (k, 3)."""
    P = vertices[triangles]
    to_next = np.roll(P, -1, axis=1) - P
    to_prev = np.roll(P, 1, axis=1) - P
    cosine = np.einsum("tkj,tkj->tk", to_next, to_prev) / np.maximum(
        np.linalg.norm(to_next, axis=2) * np.linalg.norm(to_prev, axis=2), 1e-300)
    return np.arccos(np.clip(cosine, -1.0, 1.0)).min(axis=1)


def _flip_pass(vertices, faces, surface, max_passes=20, fixed=None):
    """Flip edges to untangle folds and to raise the smallest angles.

    Two kinds of flip, at most one per triangle in each pass:

    - an untangling flip, where the two triangles are coplanar, one of them does not face the
      target (QSlim left it folded flat over its neighbour), and both flipped triangles do;
    - a shape flip across a planar edge (dihedral angle under :data:`PLANAR_ANGLE`, so the
      shape is kept) where it raises the smaller of the two triangles' smallest angles,
      neither flipped triangle turns away from the pair's mean normal and both face the target.

    Untangling flips go first, then shape flips by their gain. The ``fixed`` edges ((k, 2)
    int64 vertex pairs or None) are never flipped. Returns the new faces.
    """
    facing = None  # of every triangle; a pass finds it for the flipped triangles only
    for _ in range(max_passes):
        edges, halfedges = _edge_halfedges(faces)
        a, b, c, f1 = _wings(faces, halfedges[:, 0])
        _, _, d, f2 = _wings(faces, halfedges[:, 1])
        normals = unit_face_normals(vertices, faces)
        if facing is None:
            facing = _facing_target(vertices, faces, normals, surface)
        new_first = np.stack([a, d, c], axis=1)
        new_second = np.stack([d, b, c], axis=1)
        n_first = face_cross(vertices, new_first)
        n_second = face_cross(vertices, new_second)

        def agree(direction):
            return (np.einsum("ij,ij->i", n_first, direction) > 0) & (
                np.einsum("ij,ij->i", n_second, direction) > 0)

        valence = np.bincount(edges.reshape(-1), minlength=len(vertices))
        n = len(vertices)
        new_code = np.minimum(c, d) * n + np.maximum(c, d)
        fresh = ~np.isin(new_code, edges[:, 0] * n + edges[:, 1])
        allowed = fresh & (c != d) & (valence[a] > 3) & (valence[b] > 3)
        if fixed is not None:
            allowed &= ~_is_fixed(edges, fixed, n)
        alignment = np.einsum("ij,ij->i", normals[f1], normals[f2])
        flat = alignment > np.cos(PLANAR_ANGLE)
        untangle = allowed & ~(facing[f1] & facing[f2]) & (np.abs(alignment)
                                                          > np.cos(PLANAR_ANGLE))
        folded = np.flatnonzero(untangle)
        reference = np.zeros((len(edges), 3))
        reference[folded] = _target_normal(surface, 0.25 * (
            vertices[a[folded]] + vertices[b[folded]] + vertices[c[folded]]
            + vertices[d[folded]]))
        untangle &= agree(reference)
        before = np.minimum(_min_angles(vertices, faces[f1]), _min_angles(vertices, faces[f2]))
        after = np.minimum(_min_angles(vertices, new_first), _min_angles(vertices, new_second))
        gain = after - before
        reshape = allowed & flat & facing[f1] & facing[f2] & agree(normals[f1] + normals[f2]) \
            & (gain > 1e-6)
        # both flipped triangles must face the target: untangling then raises the triangles
        # facing it and reshaping keeps them, so no flip is undone later (without this, flips
        # can go back and forth until max_passes)
        wanted = np.flatnonzero(untangle | reshape)
        first_facing, second_facing = (np.zeros(len(edges), dtype=bool) for _ in range(2))
        first_facing[wanted] = _facing_target(vertices, new_first[wanted], None, surface)
        second_facing[wanted] = _facing_target(vertices, new_second[wanted], None, surface)
        new_facing = first_facing & second_facing
        untangle &= new_facing
        reshape &= new_facing
        order = np.concatenate([np.flatnonzero(untangle), np.flatnonzero(reshape)[
            np.argsort(-gain[reshape], kind="stable")]])
        chosen = order[_disjoint(order, np.stack([f1, f2], axis=1))[order]]
        # two flips in one pass must not create the same new edge
        chosen = chosen[np.sort(np.unique(new_code[chosen], return_index=True)[1])]
        if not len(chosen):
            return faces
        faces = faces.copy()
        faces[f1[chosen]] = new_first[chosen]
        faces[f2[chosen]] = new_second[chosen]
        facing = facing.copy()
        facing[f1[chosen]] = first_facing[chosen]
        facing[f2[chosen]] = second_facing[chosen]
    return faces


def _facing_target(vertices, faces, normals, surface):
    """(m,) bool triangles within 60 degrees of the target's normal nearest their centroid
    (``normals``: their (m, 3) unit normals, or None to compute them)."""
    if normals is None:
        normals = unit_face_normals(vertices, faces)
    reference = _target_normal(surface, vertices[faces].mean(axis=1))
    return np.einsum("ij,ij->i", normals, reference) > MIN_NORMAL_AGREEMENT


def _target_normal(surface, points):
    """(k, 3) float64 unit normal of the target triangle nearest each of ``points`` (k, 3)
    (the triangle's own normal: enough to tell which way a coarse triangle faces)."""
    return surface.face_normals[surface.nearest(points).face]

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Triangle-triangle intersection test for whole meshes (vectorised).

Broad phase: a bounding-box hierarchy traversed against itself finds the face
pairs whose boxes overlap (or, for a mesh searched again and again as it moves, a
filter of the pairs found once for boxes holding each face's whole motion). Narrow
phase: two non-coplanar triangles intersect exactly when an edge of one crosses the
other; for triangles sharing a vertex only the edges opposite that vertex can cross.
Edge-adjacent pairs cannot cross without a fold that the orientation check already
rejects, so they are skipped. Touching contacts within ``core.tolerances.CONTACT`` of the
bounding-box diagonal and exactly coplanar overlaps are not reported.
"""
import numpy as np

from core.geometry import morton_codes, unit_face_normals
from core.tolerances import CONTACT

_CHUNK = 400_000


def find_self_intersections(vertices, faces, among=None, candidates=None):
    """Pairs of faces that intersect each other.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    among : (m,) bool or None, test only the pairs with at least one face marked (for a
        mesh of which only the marked faces moved since the pairs were last found);
        None tests all.
    candidates : (c, 2) int64 or None, face pairs that include every pair whose bounding
        boxes overlap now (:func:`box_pairs` of boxes holding each face wherever it may
        have moved); only these are tested. None: the pairs are found from the faces.

    Returns
    -------
    pairs : (k, 2) int64, ``pairs[:, 0] < pairs[:, 1]``, sorted.
    """
    eps = CONTACT * float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if candidates is None:
        tri = vertices[faces]
        lo, hi = face_boxes(tri)
        return _really_intersecting(vertices, faces, tri, box_pairs(lo, hi, among), eps)
    # only the faces of the candidates with a marked face are looked at, renumbered in their
    # order (so each pair keeps its order and the sorted pairs stay sorted) and numbered back
    if among is not None:
        candidates = candidates[among[candidates[:, 0]] | among[candidates[:, 1]]]
    used = np.zeros(len(faces), dtype=bool)
    used[candidates.reshape(-1)] = True
    numbers = np.flatnonzero(used)
    renumbered = (np.cumsum(used) - 1)[candidates]
    tri = vertices[faces[numbers]]
    lo, hi = face_boxes(tri)
    return numbers[_really_intersecting(vertices, faces[numbers], tri,
                                        _overlapping(renumbered, lo, hi), eps)]


def _really_intersecting(vertices, faces, tri, pairs, eps):
    """(k, 2) int64 the rows of ``pairs`` ((p, 2) int64 into ``faces``, whose corners are
    ``tri``) that intersect (the narrow phase), sorted; ``eps`` the contact tolerance."""
    normal = unit_face_normals(vertices, faces)
    offset = np.einsum("ij,ij->i", normal, tri[:, 0])
    hits = []
    for start in range(0, len(pairs), _CHUNK):
        chunk = pairs[start:start + _CHUNK]
        # the second order is tested only on the pairs that passed the first
        chunk = chunk[_straddle(tri, normal, offset, chunk[:, 0], chunk[:, 1], eps)]
        chunk = chunk[_straddle(tri, normal, offset, chunk[:, 1], chunk[:, 0], eps)]
        hits.append(chunk[_pairs_intersect(tri, faces, chunk, normal, eps)])
    hits = np.concatenate(hits) if hits else np.zeros((0, 2), dtype=np.int64)
    return hits[np.lexsort((hits[:, 1], hits[:, 0]))]


def _straddle(tri, normal, offset, a, b, eps):
    """(p,) bool: triangle ``a`` has corners strictly on both sides of triangle ``b``'s plane.

    Pairs failing this for either order cannot cross (they at most touch), so this cheap
    test removes most candidates before the edge tests.
    """
    side = np.einsum("pkd,pd->pk", tri[a], normal[b]) - offset[b][:, None]
    above, below = side > eps, side < -eps
    return (above[:, 0] | above[:, 1] | above[:, 2]) & (below[:, 0] | below[:, 1] | below[:, 2])


def face_boxes(tri):
    """Bounding boxes of triangles ``tri`` ((m, 3, 3) float64): lo, hi, each (m, 3).

    The corners' minimum and maximum column by column (numpy's reductions over the middle
    axis of three are several times slower).
    """
    lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
    hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    return lo, hi


def box_pairs(lo, hi, among=None):
    """(p, 2) int64 pairs of boxes that overlap (i < j; touching counts).

    A bounding-volume hierarchy over the boxes ``lo``, ``hi`` ((m, 3) float64 each) in
    Morton (Z-curve) order of their centres, a complete binary tree stored level by level,
    is traversed against itself breadth-first: every level keeps only the node pairs whose
    boxes overlap, so the work follows the number of truly overlapping pairs, whatever the
    spread of box sizes. With ``among`` ((m,) bool), node pairs without a marked box below
    either node are dropped too. The boxes are kept per axis ((3, nodes) arrays) and the
    node pairs are filtered one axis at a time, so each later test gathers only the
    survivors. The pairs do not depend on the order (the tree's boxes bound their leaves).
    """
    order = np.argsort(morton_codes(lo + hi), kind="stable")
    depth = max(int(np.ceil(np.log2(max(len(lo), 2)))), 1)
    size = 1 << depth
    leaf_lo = np.full((3, size), np.inf)
    leaf_hi = np.full((3, size), -np.inf)
    leaf_lo[:, :len(lo)], leaf_hi[:, :len(lo)] = lo[order].T, hi[order].T
    leaf_marked = np.zeros(size, dtype=bool)
    leaf_marked[:len(lo)] = True if among is None else among[order]
    levels = [(leaf_lo, leaf_hi, leaf_marked)]
    while levels[0][0].shape[1] > 1:
        child_lo, child_hi, child_marked = levels[0]
        levels.insert(0, (np.minimum(child_lo[:, 0::2], child_lo[:, 1::2]),
                          np.maximum(child_hi[:, 0::2], child_hi[:, 1::2]),
                          child_marked[0::2] | child_marked[1::2]))
    # the nodes paired with themselves, kept apart from the pairs of two nodes (a < b)
    selves = np.zeros(1, dtype=np.int64)
    a = b = np.zeros(0, dtype=np.int64)
    for level_lo, level_hi, level_marked in levels[1:]:
        a = np.concatenate([2 * selves, (2 * a[:, None] + _CROSS_CHILDREN[0]).reshape(-1)])
        b = np.concatenate([2 * selves + 1, (2 * b[:, None] + _CROSS_CHILDREN[1]).reshape(-1)])
        selves = (2 * selves[:, None] + _SELF_CHILDREN).reshape(-1)
        if among is not None:
            selves = selves[level_marked[selves]]
            keep = level_marked[a] | level_marked[b]
            a, b = a[keep], b[keep]
        for axis_lo, axis_hi in zip(level_lo, level_hi):
            selves = selves[axis_lo[selves] <= axis_hi[selves]]
            keep = (axis_lo[a] <= axis_hi[b]) & (axis_lo[b] <= axis_hi[a])
            a, b = a[keep], b[keep]
    return np.sort(np.stack([order[a], order[b]], axis=1), axis=1)


def _overlapping(candidates, lo, hi):
    """(p, 2) int64 the rows of ``candidates`` ((c, 2) int64) whose boxes ``lo``, ``hi``
    ((m, 3) float64) overlap."""
    a, b = candidates[:, 0], candidates[:, 1]
    for axis in range(3):
        keep = (lo[a, axis] <= hi[b, axis]) & (lo[b, axis] <= hi[a, axis])
        a, b = a[keep], b[keep]
    return np.stack([a, b], axis=1)


_SELF_CHILDREN = np.array([0, 1], dtype=np.int64)
"""A node's children ``2 k + c``: each is paired with itself, and the two with each other."""
_CROSS_CHILDREN = np.array([[0, 0, 1, 1], [0, 1, 0, 1]], dtype=np.int64)
"""The four child pairs ``(2 a + c[0], 2 b + c[1])`` of two nodes ``a < b``."""


def _pairs_intersect(tri, faces, pairs, normal, eps):
    """(p,) bool: does each candidate pair really intersect.

    Every edge test of every pair (six for disjoint triangles, the two opposite edges for
    triangles sharing a corner) goes through one vectorised :func:`_segment_crosses_triangle`.
    ``normal`` : (m, 3) float64 unit face normals (:func:`core.geometry.unit_face_normals`).
    """
    n_shared = shared_corners(faces, pairs)
    disjoint = np.flatnonzero(n_shared == 0)
    touching = np.flatnonzero(n_shared == 1)
    # each test: the pair it belongs to, the face and first corner of the segment (its
    # edge to the next corner), and the face it may cross
    owner, segment_face, corner, crossed_face = [], [], [], []
    if len(disjoint):
        for k in range(3):
            for first, second in ((0, 1), (1, 0)):
                owner.append(disjoint)
                segment_face.append(pairs[disjoint, first])
                corner.append(np.full(len(disjoint), k))
                crossed_face.append(pairs[disjoint, second])
    if len(touching):
        shared = (faces[pairs[touching, 0]][:, :, None]
                  == faces[pairs[touching, 1]][:, None, :])
        corner_a = shared.any(axis=2).argmax(axis=1)
        corner_b = shared.any(axis=1).argmax(axis=1)
        for first, second, at in ((0, 1, corner_a), (1, 0, corner_b)):
            owner.append(touching)
            segment_face.append(pairs[touching, first])
            corner.append((at + 1) % 3)
            crossed_face.append(pairs[touching, second])
    result = np.zeros(len(pairs), dtype=bool)
    if owner:
        owner, segment_face = np.concatenate(owner), np.concatenate(segment_face)
        corner, crossed_face = np.concatenate(corner), np.concatenate(crossed_face)
        hit = _segment_crosses_triangle(tri[segment_face, corner],
                                        tri[segment_face, (corner + 1) % 3],
                                        tri[crossed_face], normal[crossed_face], eps)
        result[owner[hit]] = True
    return result


def shared_corners(faces, pairs):
    """(p,) int8 corners that the two faces of each pair ((p, 2) int64 into ``faces``,
    (m, 3) int64) have in common: 2 for faces sharing an edge, which never cross."""
    first, second = faces[pairs[:, 0]], faces[pairs[:, 1]]
    shared = np.zeros(len(pairs), dtype=np.int8)
    for a in range(3):
        for b in range(3):
            shared += first[:, a] == second[:, b]
    return shared


def _segment_crosses_triangle(p0, p1, triangle, normal, eps):
    """(p,) bool: segment p0-p1 passes strictly through the interior of the triangle.

    p0, p1 : (p, 3); triangle : (p, 3, 3); normal : (p, 3) its unit normal (zero rows for
    zero-area triangles, which nothing crosses).
    """
    a, b, c = triangle[:, 0], triangle[:, 1], triangle[:, 2]
    d0 = np.einsum("ij,ij->i", p0 - a, normal)
    d1 = np.einsum("ij,ij->i", p1 - a, normal)
    crosses = ((d0 > eps) & (d1 < -eps)) | ((d0 < -eps) & (d1 > eps))
    t = d0 / np.where(crosses, d0 - d1, 1.0)
    q = p0 + t[:, None] * (p1 - p0)
    inside = np.ones(len(p0), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        edge = v - u
        side = np.einsum("ij,ij->i", np.cross(edge, q - u), normal)
        inside &= side > eps * np.linalg.norm(edge, axis=1)
    return crosses & inside

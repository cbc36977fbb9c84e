# SPDX-License-Identifier: LGPL-2.1-or-later
"""Triangle-triangle intersection test for whole meshes.

Broad phase: a bounding-box hierarchy traversed against itself finds the face
pairs whose boxes overlap (or, for a mesh searched again and again as it moves, a
filter of the pairs found once for boxes holding each face's whole motion). Narrow
phase: two non-coplanar triangles intersect exactly when an edge of one crosses the
other; for triangles sharing a vertex only the edges opposite that vertex can cross.
Edge-adjacent pairs cannot cross without a fold that the orientation check already
rejects, so they are skipped. Touching contacts within ``core.tolerances.CONTACT`` of the
bounding-box diagonal and exactly coplanar overlaps are not reported.

The tree's traversal (:mod:`core.box_tree`) and the narrow phase are compiled with
numba: one loop over the pairs, so a fit's hundred searches do not each pay numpy's
per-call cost (the result is the same bit for bit). Compiled functions are cached on disk,
so only the first run on a machine compiles them (a few seconds).
"""
import numpy as np

from core.box_tree import box_pairs, face_boxes
from core.compiled import by_rows, keeps_interrupts, numba
from core.tolerances import CONTACT


@keeps_interrupts
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
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    eps = CONTACT * float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if candidates is None:
        candidates = box_pairs(*face_boxes(vertices[faces]), among)
        among = None
    candidates = np.ascontiguousarray(candidates, dtype=np.int64).reshape(-1, 2)
    marked = np.zeros(0, dtype=np.bool_) if among is None else np.asarray(among, dtype=np.bool_)
    hits = candidates[by_rows(_intersecting, (2,), vertices, faces, candidates, marked, eps)]
    return np.sort(hits, axis=1)[np.lexsort((hits.max(axis=1), hits.min(axis=1)))]


@numba.njit(cache=True, nogil=True)
def _intersecting(vertices, faces, pairs, marked, eps):
    """(p,) bool: the faces of each pair ((p, 2) int64) intersect (the narrow phase).

    A pair is tested only when ``marked`` ((m,) bool, or empty for all) marks one of its
    faces and their bounding boxes overlap. Each face must have corners strictly (beyond
    ``eps``, model units) on both sides of the other's plane; then an edge of one must
    cross the other (:func:`_edge_crosses`): any of the six for disjoint faces, the edge
    opposite the shared corner for faces sharing one, none for faces sharing an edge.
    """
    normal, offset, lo, hi = _face_planes_and_boxes(vertices, faces)
    test_all = marked.shape[0] == 0
    result = np.zeros(pairs.shape[0], dtype=np.bool_)
    for i in range(pairs.shape[0]):
        a, b = pairs[i, 0], pairs[i, 1]
        if not (test_all or marked[a] or marked[b]):
            continue
        if (lo[a, 0] > hi[b, 0] or lo[b, 0] > hi[a, 0] or lo[a, 1] > hi[b, 1]
                or lo[b, 1] > hi[a, 1] or lo[a, 2] > hi[b, 2] or lo[b, 2] > hi[a, 2]):
            continue  # the boxes are apart (numba's cache forbids box_tree's test here)
        if not (_straddles(vertices, faces[a], normal[b], offset[b], eps)
                and _straddles(vertices, faces[b], normal[a], offset[a], eps)):
            continue
        shared, corner_a, corner_b = 0, -1, -1
        for j in range(3):
            for k in range(3):
                if faces[a, j] == faces[b, k]:
                    shared += 1
                    corner_a, corner_b = j, k
        if shared == 0:
            for k in range(3):
                if (_edge_crosses(vertices, faces[a], k, faces[b], normal[b], eps)
                        or _edge_crosses(vertices, faces[b], k, faces[a], normal[a], eps)):
                    result[i] = True
                    break
        elif shared == 1:
            result[i] = (
                _edge_crosses(vertices, faces[a], (corner_a + 1) % 3, faces[b], normal[b], eps)
                or _edge_crosses(vertices, faces[b], (corner_b + 1) % 3, faces[a], normal[a],
                                 eps))
    return result


@numba.njit(inline="always")
def _face_planes_and_boxes(vertices, faces):
    """Unit normals (m, 3) (zero for zero-area faces), plane offsets ``normal . a`` (m,) and
    bounding boxes lo, hi ((m, 3) each) of the faces, as numpy's
    :func:`core.geometry.unit_face_normals` rounds them."""
    m = faces.shape[0]
    normal = np.zeros((m, 3))
    offset = np.zeros(m)
    lo = np.empty((m, 3))
    hi = np.empty((m, 3))
    for f in range(m):
        a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        cross = _cross(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
        length = np.sqrt(cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2])
        if length > 0:
            for d in range(3):
                normal[f, d] = cross[d] / length
        offset[f] = normal[f, 0] * a[0] + normal[f, 1] * a[1] + normal[f, 2] * a[2]
        for d in range(3):
            lo[f, d] = min(min(a[d], b[d]), c[d])
            hi[f, d] = max(max(a[d], b[d]), c[d])
    return normal, offset, lo, hi


@numba.njit(inline="always")
def _cross(ux, uy, uz, vx, vy, vz):
    """``u x v`` as a tuple of three floats (numpy's ``cross`` rounding)."""
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@numba.njit(inline="always")
def _straddles(vertices, corners, normal, offset, eps):
    """The face with vertex numbers ``corners`` (3,) has corners more than ``eps`` on both
    sides of the plane ``normal . x = offset``. Pairs failing this for either order cannot
    cross (they at most touch), so this cheap test removes most pairs before the edge
    tests."""
    above = below = False
    for k in range(3):
        p = vertices[corners[k]]
        side = p[0] * normal[0] + p[1] * normal[1] + p[2] * normal[2] - offset
        above = above or side > eps
        below = below or side < -eps
    return above and below


@numba.njit(inline="always")
def _edge_crosses(vertices, corners, k, crossed, normal, eps):
    """The edge from corner ``k`` to corner ``k + 1`` of the face with vertex numbers
    ``corners`` passes strictly through the interior of the face ``crossed`` (3,), whose
    unit normal is ``normal`` (3,) (zero for a zero-area face, which nothing crosses):
    its ends lie more than ``eps`` on either side of the plane, and the crossing point more
    than ``eps`` times each edge's length inside each of its edges."""
    p0, p1 = vertices[corners[k]], vertices[corners[(k + 1) % 3]]
    a = vertices[crossed[0]]
    d0 = (p0[0] - a[0]) * normal[0] + (p0[1] - a[1]) * normal[1] + (p0[2] - a[2]) * normal[2]
    d1 = (p1[0] - a[0]) * normal[0] + (p1[1] - a[1]) * normal[1] + (p1[2] - a[2]) * normal[2]
    if not ((d0 > eps and d1 < -eps) or (d0 < -eps and d1 > eps)):
        return False
    t = d0 / (d0 - d1)
    q = (p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), p0[2] + t * (p1[2] - p0[2]))
    for j in range(3):
        u, v = vertices[crossed[j]], vertices[crossed[(j + 1) % 3]]
        edge = (v[0] - u[0], v[1] - u[1], v[2] - u[2])
        side = _cross(edge[0], edge[1], edge[2], q[0] - u[0], q[1] - u[1], q[2] - u[2])
        if not (side[0] * normal[0] + side[1] * normal[1] + side[2] * normal[2]
                > eps * np.sqrt(edge[0] * edge[0] + edge[1] * edge[1] + edge[2] * edge[2])):
            return False
    return True

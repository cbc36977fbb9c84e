# SPDX-License-Identifier: LGPL-2.1-or-later
"""First exits of rays through a closed triangle mesh, compiled with numba.

Each ray ``o + t d`` (``d`` a unit vector) is cast through the tree of
:mod:`core.box_tree` over the triangles' bounding boxes: a node whose box the segment
``0 <= t <= best`` misses (slab test) is skipped, ``best`` being the nearest exit found so
far (at first the ray's length). Each triangle in a reached leaf gets the float64
Moeller-Trumbore test with a barycentric tolerance, so a ray through an edge or a vertex
hits one of the triangles there; an exit counts when the ray leaves the solid there
(``d . m > 0``, ``m`` the triangle's outward unit normal) beyond a small ``t_low``, so the
triangles around a ray's own start vertex, which it enters, never count. Equal distances
go to the lower triangle number.

Before this cast (session 33) libigl's unbounded ``intersect_ray_first`` ran first and a
numpy search re-cast the rays it missed: 22 ms for the 4,524 thickness rays of
idler_riser's fitted limit surface, plus 7 ms to build its tree, against about 3 ms here.
"""
import numpy as np

from core.box_tree import build_tree, face_boxes, leaf_boxes, numba, tree_order

STACK_DEPTH = 64
"""Room of the traversal stack (nodes): one per level of the tree is pushed at most."""


def first_exits(tri, normals, origins, directions, max_length, t_low, edge_tol, pad):
    """Nearest exit of every ray within ``max_length``.

    Parameters
    ----------
    tri : (m, 3, 3) float64 triangle corners (model units), m >= 1.
    normals : (m, 3) float64 outward unit normals (zero rows for zero-area triangles,
        which no ray leaves through).
    origins : (k, 3) float64; directions : (k, 3) float64 unit vectors.
    max_length : float > 0, ray length (model units); exits farther away are not found.
    t_low : float >= 0, exits at ``t <= t_low`` do not count.
    edge_tol : float >= 0, barycentric tolerance of the triangle test (dimensionless).
    pad : float >= 0, the triangles' boxes are widened by this much (model units), to hold
        the hits the tolerance admits outside a triangle and the rounding of the slab test.

    Returns
    -------
    t : (k,) float64 distance to the exit, ``inf`` where none.
    face : (k,) int64 triangle exited through, ``-1`` where none.
    uv : (k, 2) float64 barycentric ``(u, v)`` of the exit on it (zeros where none).
    """
    tri = np.ascontiguousarray(tri, dtype=np.float64)
    lo, hi = face_boxes(tri)
    lo, hi = lo - pad, hi + pad
    order = tree_order(lo, hi)
    return _cast(tri, np.ascontiguousarray(normals, dtype=np.float64), lo[order], hi[order],
                 order, np.ascontiguousarray(origins, dtype=np.float64),
                 np.ascontiguousarray(directions, dtype=np.float64),
                 float(max_length), float(t_low), float(edge_tol))


@numba.njit(cache=True, nogil=True)
def _cast(tri, normals, lo, hi, order, origins, directions, max_length, t_low, edge_tol):
    """The work of :func:`first_exits`, ``lo``, ``hi`` the padded boxes in tree ``order``."""
    m = order.shape[0]
    node_lo, node_hi, size = build_tree(lo, hi)
    k = origins.shape[0]
    t_found = np.full(k, np.inf)
    face_found = np.full(k, -1, dtype=np.int64)
    uv_found = np.zeros((k, 2))
    stack = np.empty(STACK_DEPTH, dtype=np.int64)
    for r in range(k):
        o, d = origins[r], directions[r]
        best, best_face, best_u, best_v = max_length, -1, 0.0, 0.0
        stack[0], top = 1, 1
        while top:
            top -= 1
            node = stack[top]
            if _segment_enters_box(o, d, best, node_lo[node], node_hi[node]) > best:
                continue  # missed, or entered beyond the nearest exit found since it was put
            if node < size:
                # the child entered nearer is opened first (put last): its exits cut the
                # search of the other
                near = _segment_enters_box(o, d, best, node_lo[2 * node], node_hi[2 * node])
                far = _segment_enters_box(o, d, best, node_lo[2 * node + 1],
                                          node_hi[2 * node + 1])
                first, second = 2 * node, 2 * node + 1
                if far < near:
                    first, second, near, far = second, first, far, near
                if far <= best:
                    stack[top] = second
                    top += 1
                if near <= best:
                    stack[top] = first
                    top += 1
                continue
            first, stop = leaf_boxes(node, size, m)
            for i in range(first, stop):
                f = order[i]
                if d[0] * normals[f, 0] + d[1] * normals[f, 1] + d[2] * normals[f, 2] <= 0:
                    continue  # entered or grazed, not left
                hit, t, u, v = _ray_triangle(o, d, tri[f], edge_tol)
                if not hit or t <= t_low:
                    continue
                if t < best or (t == best and (best_face < 0 or f < best_face)):
                    best, best_face, best_u, best_v = t, f, u, v
        if best_face >= 0:
            t_found[r], face_found[r] = best, best_face
            uv_found[r, 0], uv_found[r, 1] = best_u, best_v
    return t_found, face_found, uv_found


@numba.njit(inline="always")
def _segment_enters_box(o, d, length, lo, hi):
    """Where the segment ``o + t d``, ``0 <= t <= length``, enters the box ``lo``, ``hi``
    (``t``, 0 when it starts inside), or ``inf`` when it misses it (slab test; an axis the
    ray runs parallel to needs ``o`` between the slab's planes; an empty box, ``lo = inf``,
    is missed)."""
    enter, leave = 0.0, length
    for axis in range(3):
        if lo[axis] > hi[axis]:
            return np.inf
        if d[axis] == 0.0:
            if o[axis] < lo[axis] or o[axis] > hi[axis]:
                return np.inf
            continue
        near = (lo[axis] - o[axis]) / d[axis]
        far = (hi[axis] - o[axis]) / d[axis]
        if near > far:
            near, far = far, near
        enter, leave = max(enter, near), min(leave, far)
        if enter > leave:
            return np.inf
    return enter


@numba.njit(inline="always")
def _ray_triangle(o, d, corners, edge_tol):
    """Moeller-Trumbore in float64 with barycentric tolerance ``edge_tol``: whether the
    ray's line crosses the triangle ``corners`` ((3, 3), edges and corners included) and
    its ``t, u, v`` there."""
    a = corners[0]
    e1 = (corners[1, 0] - a[0], corners[1, 1] - a[1], corners[1, 2] - a[2])
    e2 = (corners[2, 0] - a[0], corners[2, 1] - a[1], corners[2, 2] - a[2])
    p = (d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0])
    det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2]
    if not abs(det) > 1e-300:
        return False, 0.0, 0.0, 0.0
    inv = 1.0 / det
    s = (o[0] - a[0], o[1] - a[1], o[2] - a[2])
    u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv
    q = (s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0])
    v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv
    t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv
    hit = u >= -edge_tol and v >= -edge_tol and u + v <= 1.0 + edge_tol
    return hit, t, u, v

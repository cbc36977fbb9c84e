# SPDX-License-Identifier: LGPL-2.1-or-later
"""A compiled bounding-box tree over triangles and its three queries: overlapping pairs of
boxes, the nearest triangle to a point, and the first exit of a ray.

The boxes are put in the order of a k-d tree of their centres (:func:`tree_order`) and
grouped ``LEAF_BOXES`` to a leaf; the leaves are the bottom level of a complete binary tree
stored as a heap: node 1 is the root, node ``k`` has the children ``2 k`` and ``2 k + 1``,
and leaf ``size + l`` holds the boxes ``LEAF_BOXES l`` to ``LEAF_BOXES (l + 1) - 1`` in tree
order (empty leaves pad the tree to a power of two). Every node's box bounds its leaves'
boxes, so a query that misses a node's box misses everything below it, whatever the order.

Overlapping pairs (:func:`box_pairs`, the broad phase of
:mod:`core.self_intersection`): the tree is traversed against itself; only node pairs whose
boxes overlap are opened.

Closest points (:func:`nearest_triangles`): each point walks the tree nearest box first
and skips every node whose box lies farther than the nearest triangle found so far; each
triangle reached gets Ericson's region test (:func:`closest_on_triangles`, the same
arithmetic), and equal distances go to the lower triangle number.

Rivals (:func:`rival_triangles`): the same walk, bounded by a point's distance to its
closest point plus a slack, keeps the nearest triangle whose closest point lies in another
direction from the point (a point on the mesh's medial axis has two).

Rays (:func:`first_exits`): each ray ``o + t d`` (``d`` a unit vector) skips every node
whose box the segment ``0 <= t <= best`` misses (slab test), ``best`` being the nearest
exit found so far (at first the ray's length); the child entered nearer is opened first.
Each triangle in a reached leaf gets the float64 Moeller-Trumbore test with a barycentric
tolerance, so a ray through an edge or a vertex hits one of the triangles there; an exit
counts when the ray leaves the solid there (``d . m > 0``, ``m`` the triangle's outward
unit normal) beyond a small ``t_low``, so the triangles around a ray's own start vertex,
which it enters, never count. Equal distances go to the lower triangle number.

This tree replaces libigl's (``igl.AABB``) for the last two queries: libigl's ray query
is unbounded and misses some crossings exactly on an edge or a vertex, which then had to be
cast again by a numpy search, and both of its queries are slower on the fit's point and ray
sets than this tree, whose build is included in the query.

Every function is compiled with numba and cached on disk (``cache=True``: ``__pycache__``
beside this file, or the user's cache folder when that is read-only), so only the first run
on a machine compiles them. numba's cache of a function is renewed when its own file
changes, not when a compiled function of another file that it calls does: so no compiled
function here calls one of another module, nor one of another module one of these.
"""
from dataclasses import dataclass

import numpy as np

from core.compiled import ROW_BLOCK, by_rows, keeps_interrupts, numba, worker_pool

LEAF_BOXES = 4
"""Boxes per leaf: a few boxes a leaf make the tree shallower and the self-overlap search
of a limit mesh faster than one box a leaf."""
STACK_DEPTH = 64
"""Room of the traversal stack (nodes): one per level of the tree is pushed at most."""


def face_boxes(tri):
    """Bounding boxes of triangles ``tri`` ((m, 3, 3) float64): lo, hi, each (m, 3).

    The corners' minimum and maximum column by column (numpy's reductions over the middle
    axis of three are several times slower).
    """
    lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
    hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    return lo, hi


@keeps_interrupts
def tree_order(lo, hi):
    """(m,) int64 the boxes ``lo``, ``hi`` ((m, 3) float64, m >= 1) in tree order.

    Top down, each node's boxes are split at its capacity's half (the capacity of a node
    ``LEAF_BOXES`` times the leaves below it) into the boxes with the lower and the higher
    centres along the axis on which the node's centres spread most (ties by number, so the
    order is the same for the same boxes; a selection, not a sort, :func:`_select`): a k-d
    tree's order, whose nodes are compact. (In Morton order, with the tree's fixed grouping,
    leaves straddling the Z-curve's jumps were up to 0.7 of the diagonal wide and a short ray
    opened 260 leaves.)
    """
    centres = np.ascontiguousarray(lo + hi, dtype=np.float64)
    m = len(centres)
    capacity = LEAF_BOXES
    while capacity < m:
        capacity *= 2
    order = np.arange(m)
    if m < 2 * ROW_BLOCK or capacity <= LEAF_BOXES:
        _kd_levels(centres, order, 0, m, capacity, LEAF_BOXES)
        return order
    # the root's split, then its two children's boxes (apart in ``order``) on two cores
    half = capacity // 2
    _kd_levels(centres, order, 0, m, capacity, half)
    pool, _ = worker_pool()
    second = pool.submit(_kd_levels, centres, order, half, m, half, LEAF_BOXES)
    _kd_levels(centres, order, 0, half, half, LEAF_BOXES)
    second.result()
    return order


@dataclass(frozen=True)
class TriangleTree:
    """The tree over a mesh's triangles, built once, queried often.

    tri : (m, 3, 3) float64 triangle corners (model units).
    order : (m,) int64 the triangles in tree order.
    node_lo, node_hi : (2 size, 3) float64 node boxes (:func:`_build_tree`), the triangles'
        boxes widened by the tree's pad.
    """

    tri: np.ndarray
    order: np.ndarray
    node_lo: np.ndarray
    node_hi: np.ndarray


@keeps_interrupts
def triangle_tree(tri, pad):
    """:class:`TriangleTree` over ``tri`` ((m, 3, 3) float64, m >= 1), the triangles' boxes
    widened by ``pad`` (model units, >= 0: for rays, more than the hits the barycentric
    tolerance admits outside a triangle and the slab test's rounding)."""
    tri = np.ascontiguousarray(tri, dtype=np.float64)
    lo, hi = face_boxes(tri)
    lo, hi = lo - pad, hi + pad
    order = tree_order(lo, hi)
    node_lo, node_hi, _ = _build_tree(np.ascontiguousarray(lo[order]),
                                      np.ascontiguousarray(hi[order]))
    return TriangleTree(tri, order, node_lo, node_hi)


@keeps_interrupts
def box_pairs(lo, hi, among=None):
    """(p, 2) int64 pairs of boxes that overlap (i < j in each row; touching counts).

    The tree over the boxes ``lo``, ``hi`` ((m, 3) float64 each) is traversed against itself
    (:func:`_overlaps_below`): only node pairs whose boxes overlap are opened, so the work
    follows the number of truly overlapping pairs, whatever the spread of box sizes. With ``among`` ((m,) bool), node pairs without
    a marked box below either node are dropped too. The rows come in the order of the
    traversal (the same for the same boxes). The traversal opens the node pairs of the top
    ``SPLIT_LEVELS`` levels in the order it pops them (:func:`_start_pairs`) and traverses
    below each of them in turn, those in blocks on the cores (:func:`core.compiled.by_rows`):
    a traversal below a node pair ends before the next pair is popped, so the rows are
    those of one traversal from the root.
    """
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    if not len(lo):
        return np.zeros((0, 2), dtype=np.int64)
    order = tree_order(lo, hi)
    marked = np.ones(len(lo), dtype=np.bool_) if among is None else np.asarray(among, np.bool_)
    lo, hi, marked = lo[order], hi[order], marked[order]
    node_lo, node_hi, node_marked = _marked_tree(lo, hi, marked)
    starts = _start_pairs(len(node_lo) // 2, SPLIT_LEVELS)
    return by_rows(_overlaps_below, (7,), lo, hi, marked, order, node_lo, node_hi, node_marked,
                   starts, least=1)


SPLIT_LEVELS = 3
"""Levels of the tree whose node pairs :func:`box_pairs` opens before traversing below each
(up to 36 pairs: enough blocks for the cores)."""


def _start_pairs(size, levels):
    """(k, 2) int64 the node pairs ``levels`` levels below the root pair (or leaf pairs, in a
    tree of ``size`` leaves), in the order :func:`_overlaps_below`'s stack pops them."""

    def below(a, b, level):
        if level == 0 or a >= size:
            return [(a, b)]
        pushed = ([(2 * a, 2 * a), (2 * a + 1, 2 * a + 1), (2 * a, 2 * a + 1)] if a == b else
                  [(2 * a, 2 * b), (2 * a, 2 * b + 1), (2 * a + 1, 2 * b), (2 * a + 1, 2 * b + 1)])
        return [pair for child in reversed(pushed) for pair in below(*child, level - 1)]

    return np.array(below(1, 1, levels), dtype=np.int64).reshape(-1, 2)


@keeps_interrupts
def nearest_triangles(tree, points):
    """(k,) int64 the triangle of ``tree`` (:class:`TriangleTree`) nearest to each of
    ``points`` ((k, 3) float64), the lower number where two are equally near."""
    return by_rows(_nearest, (4,), tree.tri, tree.order, tree.node_lo, tree.node_hi,
                   np.ascontiguousarray(points, dtype=np.float64))


@keeps_interrupts
def rival_triangles(tree, points, closest, distance, slack, cosine):
    """For each point, the nearest triangle of ``tree`` whose closest point lies in another
    direction: a point on the medial axis of the mesh (midway between the two walls of a
    thin member, on the bisector of a concave corner) is as near to two places, and which
    of them :func:`nearest_triangles` returns is decided by rounding.

    Parameters
    ----------
    tree : TriangleTree
    points : (k, 3) float64; closest : (k, 3) float64 their closest points on the mesh;
    distance : (k,) float64 the distances to them (model units).
    slack : float >= 0, model units: a rival is at most ``distance + slack`` away, and a
        point at most ``slack`` from the mesh has none.
    cosine : float, a rival's direction from the point makes a cosine below this with the
        direction to ``closest``.

    Returns
    -------
    (k,) int64 tree triangle of each point's rival (the nearest, the lower number of equally
    near ones), ``-1`` where none.
    """
    return by_rows(_rivals, (4, 5, 6), tree.tri, tree.order, tree.node_lo, tree.node_hi,
                   np.ascontiguousarray(points, dtype=np.float64),
                   np.ascontiguousarray(closest, dtype=np.float64),
                   np.ascontiguousarray(distance, dtype=np.float64), float(slack),
                   float(cosine))


@keeps_interrupts
def closest_on_triangles(triangles, points):
    """Closest point on ``triangles[i]`` to ``points[i]`` (Ericson's region test).

    Parameters
    ----------
    triangles : (k, 3, 3) float64, corners ``a, b, c``.
    points : (k, 3) float64

    Returns
    -------
    closest : (k, 3) float64
    bary : (k, 3) float64 barycentric coordinates of ``closest`` (sum 1).
    region : (k,) int8, 0 face interior, 1..3 edges ab, bc, ca, 4..6 corners a, b, c.
    """
    return _closest_on_triangles(np.ascontiguousarray(triangles, dtype=np.float64),
                                 np.ascontiguousarray(points, dtype=np.float64))


@keeps_interrupts
def first_exits(tree, normals, origins, directions, max_length, t_low, edge_tol):
    """Nearest exit of every ray within ``max_length``.

    Parameters
    ----------
    tree : TriangleTree of the mesh (its pad holding ``edge_tol``'s hits).
    normals : (m, 3) float64 the triangles' outward unit normals (zero rows for zero-area
        triangles, which no ray leaves through).
    origins : (k, 3) float64; directions : (k, 3) float64 unit vectors.
    max_length : float > 0, ray length (model units); exits farther away are not found.
    t_low : float >= 0, exits at ``t <= t_low`` do not count.
    edge_tol : float >= 0, barycentric tolerance of the triangle test (dimensionless).

    Returns
    -------
    t : (k,) float64 distance to the exit, ``inf`` where none.
    face : (k,) int64 triangle exited through, ``-1`` where none.
    uv : (k, 2) float64 barycentric ``(u, v)`` of the exit on it (zeros where none).
    """
    return by_rows(_cast, (5, 6), tree.tri, np.ascontiguousarray(normals, dtype=np.float64),
                   tree.order, tree.node_lo, tree.node_hi,
                   np.ascontiguousarray(origins, dtype=np.float64),
                   np.ascontiguousarray(directions, dtype=np.float64),
                   float(max_length), float(t_low), float(edge_tol))


@numba.njit(cache=True, nogil=True)
def _kd_levels(centres, order, first, stop, capacity, smallest):
    """Put ``order[first:stop]`` in the order of :func:`tree_order` from nodes of ``capacity``
    boxes (a power of two times ``LEAF_BOXES``, ``first`` a multiple of it) down to nodes of
    ``smallest`` boxes, in place; ``centres`` ((m, 3) float64) are the box centres."""
    while capacity > smallest:
        half = capacity // 2
        for start in range(first, stop, capacity):
            end = min(start + capacity, stop)
            if end - start <= half:
                continue  # all in the first child
            low = np.full(3, np.inf)
            high = np.full(3, -np.inf)
            for i in range(start, end):
                for d in range(3):
                    low[d] = min(low[d], centres[order[i], d])
                    high[d] = max(high[d], centres[order[i], d])
            _select(order, centres[:, np.argmax(high - low)], start, end, start + half)
        capacity = half


@numba.njit(inline="always")
def _select(order, keys, start, stop, kth):
    """Rearrange ``order[start:stop]`` in place so that the boxes before position ``kth``
    come before (:func:`_before`) those from it on (quickselect, Lomuto's partition about the
    median of three)."""
    first, last = start, stop - 1
    while first < last:
        middle = (first + last) // 2
        # the median of the three to the end, as the pivot
        if _before(keys, order[middle], order[first]):
            order[first], order[middle] = order[middle], order[first]
        if _before(keys, order[last], order[first]):
            order[first], order[last] = order[last], order[first]
        if _before(keys, order[middle], order[last]):
            order[middle], order[last] = order[last], order[middle]
        pivot, store = order[last], first
        for i in range(first, last):
            if _before(keys, order[i], pivot):
                order[i], order[store] = order[store], order[i]
                store += 1
        order[store], order[last] = order[last], order[store]
        if store == kth:
            return
        if kth < store:
            last = store - 1
        else:
            first = store + 1


@numba.njit(inline="always")
def _before(keys, a, b):
    """Box ``a`` comes before box ``b``: a lower key, or the same key and a lower number."""
    return keys[a] < keys[b] or (keys[a] == keys[b] and a < b)


@numba.njit(cache=True, nogil=True)
def _build_tree(lo, hi):
    """Node boxes of the tree over the boxes ``lo``, ``hi`` ((m, 3) float64, in tree order).

    Returns
    -------
    node_lo, node_hi : (2 size, 3) float64, node ``k``'s box (node 0 unused; empty nodes
        have ``lo = inf``, ``hi = -inf`` and overlap nothing).
    size : int, the number of leaves (a power of two), leaf ``l`` being node ``size + l``.
    """
    m = lo.shape[0]
    size = 1
    while size * LEAF_BOXES < m:
        size *= 2
    node_lo = np.full((2 * size, 3), np.inf)
    node_hi = np.full((2 * size, 3), -np.inf)
    for i in range(m):
        leaf = size + i // LEAF_BOXES
        for d in range(3):
            node_lo[leaf, d] = min(node_lo[leaf, d], lo[i, d])
            node_hi[leaf, d] = max(node_hi[leaf, d], hi[i, d])
    for k in range(size - 1, 0, -1):
        for d in range(3):
            node_lo[k, d] = min(node_lo[2 * k, d], node_lo[2 * k + 1, d])
            node_hi[k, d] = max(node_hi[2 * k, d], node_hi[2 * k + 1, d])
    return node_lo, node_hi, size


@numba.njit(cache=True, nogil=True)
def _marked_tree(lo, hi, marked):
    """Node boxes (:func:`_build_tree`) of the boxes ``lo``, ``hi`` ((m, 3) float64, in tree
    order) and (2 size,) bool: a box marked in ``marked`` ((m,) bool) lies below the node."""
    m = lo.shape[0]
    node_lo, node_hi, size = _build_tree(lo, hi)
    node_marked = np.zeros(2 * size, dtype=np.bool_)
    for leaf in range(size, 2 * size):
        first, stop = _leaf_boxes(leaf, size, m)
        node_marked[leaf] = marked[first:stop].any() if first < stop else False
    for k in range(size - 1, 0, -1):
        node_marked[k] = node_marked[2 * k] or node_marked[2 * k + 1]
    return node_lo, node_hi, node_marked


@numba.njit(cache=True, nogil=True)
def _overlaps_below(lo, hi, marked, numbers, node_lo, node_hi, node_marked, starts):
    """(p, 2) int64 the overlapping pairs (with a marked box) of the boxes ``lo``, ``hi``
    ((m, 3) float64, in tree order, ``marked`` (m,) bool) below each node pair of ``starts``
    ((k, 2) int64, one after another), as ``numbers`` ((m,) int64) of the boxes, smaller
    first; the tree is :func:`_marked_tree`'s.

    A stack holds the node pairs still to open (at most three per level for a node paired
    with itself, four for two nodes); two overlapping leaves test their boxes pair by pair.
    """
    m = lo.shape[0]
    size = node_lo.shape[0] // 2
    pairs = np.empty((m + 16, 2), dtype=np.int64)
    count = 0
    stack = np.empty((4 * 64, 2), dtype=np.int64)
    for s in range(starts.shape[0]):
        top = _push(stack, 0, starts[s, 0], starts[s, 1])
        while top:
            top -= 1
            a, b = stack[top, 0], stack[top, 1]
            if not (node_marked[a] or node_marked[b]) or \
                    not _boxes_overlap(node_lo, node_hi, a, b):
                continue
            if a >= size:  # two leaves (or one leaf with itself)
                first_a, stop_a = _leaf_boxes(a, size, m)
                first_b, stop_b = _leaf_boxes(b, size, m)
                for i in range(first_a, stop_a):
                    for j in range(i + 1 if a == b else first_b, stop_b):
                        if not (marked[i] or marked[j]) or not _boxes_overlap(lo, hi, i, j):
                            continue
                        if count == pairs.shape[0]:
                            pairs = np.concatenate((pairs, np.empty_like(pairs)))
                        pairs[count, 0] = min(numbers[i], numbers[j])
                        pairs[count, 1] = max(numbers[i], numbers[j])
                        count += 1
            elif a == b:
                top = _push(stack, top, 2 * a, 2 * a)
                top = _push(stack, top, 2 * a + 1, 2 * a + 1)
                top = _push(stack, top, 2 * a, 2 * a + 1)
            else:
                top = _push(stack, top, 2 * a, 2 * b)
                top = _push(stack, top, 2 * a, 2 * b + 1)
                top = _push(stack, top, 2 * a + 1, 2 * b)
                top = _push(stack, top, 2 * a + 1, 2 * b + 1)
    return pairs[:count].copy()


@numba.njit(cache=True, nogil=True)
def _nearest(tri, order, node_lo, node_hi, points):
    """The work of :func:`nearest_triangles`."""
    m, size = order.shape[0], node_lo.shape[0] // 2
    found = np.full(points.shape[0], -1, dtype=np.int64)
    stack = np.empty(STACK_DEPTH, dtype=np.int64)
    for r in range(points.shape[0]):
        p = points[r]
        best, best_face = np.inf, -1
        stack[0], top = 1, 1
        while top:
            top -= 1
            node = stack[top]
            if _box_distance(p, node_lo[node], node_hi[node]) > best:
                continue  # farther than the nearest triangle found since it was put
            if node < size:
                top = _push_children_near(stack, top, node, best, p, node_lo, node_hi)
                continue
            first_box, stop = _leaf_boxes(node, size, m)
            for i in range(first_box, stop):
                f = order[i]
                v, w, _ = _closest_on_triangle(p, tri[f])
                distance = 0.0
                for d in range(3):
                    gap = _gap(p, tri[f], v, w, d)
                    distance += gap * gap
                if distance < best or (distance == best and f < best_face):
                    best, best_face = distance, f
        found[r] = best_face
    return found


@numba.njit(cache=True, nogil=True)
def _rivals(tri, order, node_lo, node_hi, points, closest, distance, slack, cosine):
    """The work of :func:`rival_triangles`."""
    m, size = order.shape[0], node_lo.shape[0] // 2
    found = np.full(points.shape[0], -1, dtype=np.int64)
    stack = np.empty(STACK_DEPTH, dtype=np.int64)
    for r in range(points.shape[0]):
        if distance[r] <= slack:
            continue
        p, c = points[r], closest[r]
        reach = (distance[r] + slack) ** 2
        best, best_face = reach, -1
        stack[0], top = 1, 1
        while top:
            top -= 1
            node = stack[top]
            if _box_distance(p, node_lo[node], node_hi[node]) > best:
                continue
            if node < size:
                top = _push_children_near(stack, top, node, best, p, node_lo, node_hi)
                continue
            first_box, stop = _leaf_boxes(node, size, m)
            for i in range(first_box, stop):
                f = order[i]
                v, w, _ = _closest_on_triangle(p, tri[f])
                squared, along = 0.0, 0.0
                for d in range(3):
                    gap = _gap(p, tri[f], v, w, d)
                    squared += gap * gap
                    along += gap * (p[d] - c[d])
                if squared > best or (squared == best and f > best_face >= 0):
                    continue
                if along >= cosine * np.sqrt(squared) * distance[r]:
                    continue  # the same place, or near it in the same direction
                best, best_face = squared, f
        found[r] = best_face
    return found


@numba.njit(cache=True, nogil=True)
def _closest_on_triangles(triangles, points):
    """The work of :func:`closest_on_triangles`."""
    k = points.shape[0]
    closest = np.empty((k, 3))
    bary = np.empty((k, 3))
    region = np.empty(k, dtype=np.int8)
    for i in range(k):
        v, w, region[i] = _closest_on_triangle(points[i], triangles[i])
        a = triangles[i, 0]
        for d in range(3):
            closest[i, d] = a[d] + v * (triangles[i, 1, d] - a[d]) + w * (triangles[i, 2, d] - a[d])
        bary[i, 0], bary[i, 1], bary[i, 2] = 1.0 - v - w, v, w
    return closest, bary, region


@numba.njit(inline="always", error_model="numpy")
def _closest_on_triangle(p, corners):
    """Ericson's region test for the point ``p`` on the triangle ``corners`` ((3, 3)):
    ``v, w, region`` with the closest point ``a + v (b - a) + w (c - a)`` and the region
    code of :func:`closest_on_triangles` (a zero-area triangle's divisions give NaN, as in
    numpy)."""
    a, b, c = corners[0], corners[1], corners[2]
    d1 = d2 = d3 = d4 = d5 = d6 = 0.0
    for d in range(3):
        ab, ac = b[d] - a[d], c[d] - a[d]
        d1 += ab * (p[d] - a[d])
        d2 += ac * (p[d] - a[d])
        d3 += ab * (p[d] - b[d])
        d4 += ac * (p[d] - b[d])
        d5 += ab * (p[d] - c[d])
        d6 += ac * (p[d] - c[d])
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    if d1 <= 0 and d2 <= 0:
        return 0.0, 0.0, 4
    if d3 >= 0 and d4 <= d3:
        return 1.0, 0.0, 5
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        return d1 / (d1 - d3), 0.0, 1
    if d6 >= 0 and d5 <= d6:
        return 0.0, 1.0, 6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        return 0.0, d2 / (d2 - d6), 3
    if va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        e = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 1.0 - e, e, 2
    denom = va + vb + vc
    safe = denom if denom != 0 else 1.0
    return vb / safe, vc / safe, 0


@numba.njit(inline="always")
def _box_distance(p, lo, hi):
    """Squared distance from ``p`` to the box ``lo``, ``hi`` (``inf`` for an empty box)."""
    total = 0.0
    for d in range(3):
        if lo[d] > hi[d]:
            return np.inf
        gap = max(lo[d] - p[d], 0.0, p[d] - hi[d])
        total += gap * gap
    return total


@numba.njit(cache=True, nogil=True)
def _cast(tri, normals, order, node_lo, node_hi, origins, directions, max_length, t_low,
          edge_tol):
    """The work of :func:`first_exits`."""
    m, size = order.shape[0], node_lo.shape[0] // 2
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
                top = _push_children(stack, top, node, best,
                                     _segment_enters_box(o, d, best, node_lo[2 * node],
                                                         node_hi[2 * node]),
                                     _segment_enters_box(o, d, best, node_lo[2 * node + 1],
                                                         node_hi[2 * node + 1]))
                continue
            first, stop = _leaf_boxes(node, size, m)
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


@numba.njit(inline="always")
def _leaf_boxes(leaf, size, m):
    """The range ``first, stop`` of the boxes (tree order, ``m`` in all) of node ``leaf``."""
    first = (leaf - size) * LEAF_BOXES
    return first, min(first + LEAF_BOXES, m)


@numba.njit(inline="always")
def _boxes_overlap(lo, hi, a, b):
    """Boxes ``a`` and ``b`` of ``lo``, ``hi`` overlap on every axis (touching counts)."""
    for d in range(3):
        if lo[a, d] > hi[b, d] or lo[b, d] > hi[a, d]:
            return False
    return True


@numba.njit(inline="always")
def _push(stack, top, a, b):
    """Put the pair ``(a, b)`` on ``stack`` ((s, 2) int64) at ``top``; the new top."""
    stack[top, 0], stack[top, 1] = a, b
    return top + 1


@numba.njit(inline="always")
def _push_children_near(stack, top, node, best, p, node_lo, node_hi):
    """:func:`_push_children` keyed by the squared distances from ``p`` to the children's
    boxes."""
    return _push_children(stack, top, node, best,
                          _box_distance(p, node_lo[2 * node], node_hi[2 * node]),
                          _box_distance(p, node_lo[2 * node + 1], node_hi[2 * node + 1]))


@numba.njit(inline="always")
def _gap(p, corners, v, w, d):
    """Coordinate ``d`` of ``p`` minus that of the point ``a + v (b - a) + w (c - a)`` of the
    triangle ``corners`` ((3, 3))."""
    return p[d] - (corners[0, d] + v * (corners[1, d] - corners[0, d])
                   + w * (corners[2, d] - corners[0, d]))


@numba.njit(inline="always")
def _push_children(stack, top, node, best, key_first, key_second):
    """Put the children ``2 node`` and ``2 node + 1`` of ``node`` whose keys (a squared
    distance, or where a ray enters their box) are at most ``best`` on ``stack`` at ``top``,
    the one with the smaller key last, so that it is opened first and what it finds cuts the
    search of the other; the new top."""
    first, second = 2 * node, 2 * node + 1
    if key_second < key_first:
        first, second, key_first, key_second = second, first, key_second, key_first
    if key_second <= best:
        stack[top] = second
        top += 1
    if key_first <= best:
        stack[top] = first
        top += 1
    return top

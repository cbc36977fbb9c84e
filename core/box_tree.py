# SPDX-License-Identifier: LGPL-2.1-or-later
"""A compiled bounding-box tree, shared by the self-intersection search and the ray casts.

The boxes are put in the order of a k-d tree of their centres (:func:`tree_order`) and
grouped ``LEAF_BOXES`` to a leaf; the leaves are the bottom level of a complete binary tree stored as a heap: node 1
is the root, node ``k`` has the children ``2 k`` and ``2 k + 1``, and leaf ``size + l``
holds the boxes ``LEAF_BOXES l`` to ``LEAF_BOXES (l + 1) - 1`` in tree order (empty leaves
pad the tree to a power of two). Every node's box bounds its leaves' boxes, so a query
that misses a node's box misses everything below it, whatever the order.

The functions are compiled with numba and cached on disk (``cache=True``: ``__pycache__``
beside this file, or the user's cache folder when that is read-only), so only the first
run on a machine compiles them.
"""
import numpy as np

from core.optional_imports import optional_module

numba = optional_module("numba")

LEAF_BOXES = 4
"""Boxes per leaf (on featuretype's level-2 limit mesh, 9,920 triangles and 80,574
overlapping pairs, four take about 0.6 of the self-overlap search time of one)."""


def face_boxes(tri):
    """Bounding boxes of triangles ``tri`` ((m, 3, 3) float64): lo, hi, each (m, 3).

    The corners' minimum and maximum column by column (numpy's reductions over the middle
    axis of three are several times slower).
    """
    lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
    hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    return lo, hi


def tree_order(lo, hi):
    """(m,) int64 the boxes ``lo``, ``hi`` ((m, 3) float64, m >= 1) in tree order.

    Top down, each node's boxes are split at its capacity's half (the capacity of a node
    ``LEAF_BOXES`` times the leaves below it) into the boxes with the lower and the higher
    centres along the axis on which the node's centres spread most (ties by number, so the
    order is the same for the same boxes; a selection, not a sort, :func:`_select`): a k-d
    tree's order, whose nodes are compact. (In
    Morton order, with the tree's fixed grouping, leaves straddling the Z-curve's jumps were
    up to 0.7 of the diagonal wide and a short ray opened 260 leaves.)
    """
    centres = np.ascontiguousarray(lo + hi, dtype=np.float64)
    return _kd_order(centres, LEAF_BOXES)


@numba.njit(cache=True, nogil=True)
def _kd_order(centres, leaf_boxes_count):
    """The order of :func:`tree_order` for box centres ``centres`` ((m, 3) float64)."""
    m = centres.shape[0]
    size = 1
    while size * leaf_boxes_count < m:
        size *= 2
    order = np.arange(m)
    capacity = size * leaf_boxes_count
    while capacity > leaf_boxes_count:
        half = capacity // 2
        for start in range(0, m, capacity):
            stop = min(start + capacity, m)
            if stop - start <= half:
                continue  # all in the first child
            low = np.full(3, np.inf)
            high = np.full(3, -np.inf)
            for i in range(start, stop):
                for d in range(3):
                    low[d] = min(low[d], centres[order[i], d])
                    high[d] = max(high[d], centres[order[i], d])
            _select(order, centres[:, np.argmax(high - low)], start, stop, start + half)
        capacity = half
    return order


@numba.njit(inline="always")
def _before(keys, a, b):
    """Box ``a`` comes before box ``b``: a lower key, or the same key and a lower number."""
    return keys[a] < keys[b] or (keys[a] == keys[b] and a < b)


@numba.njit(cache=True, nogil=True)
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


@numba.njit(cache=True, nogil=True)
def build_tree(lo, hi):
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


@numba.njit(inline="always")
def leaf_boxes(leaf, size, m):
    """The range ``first, stop`` of the boxes (tree order, ``m`` in all) of node ``leaf``."""
    first = (leaf - size) * LEAF_BOXES
    return first, min(first + LEAF_BOXES, m)


@numba.njit(inline="always")
def boxes_overlap(lo, hi, a, b):
    """Boxes ``a`` and ``b`` of ``lo``, ``hi`` overlap on every axis (touching counts)."""
    for d in range(3):
        if lo[a, d] > hi[b, d] or lo[b, d] > hi[a, d]:
            return False
    return True


@numba.njit(inline="always")
def push(stack, top, a, b):
    """Put the pair ``(a, b)`` on ``stack`` ((s, 2) int64) at ``top``; the new top."""
    stack[top, 0], stack[top, 1] = a, b
    return top + 1

# SPDX-License-Identifier: LGPL-2.1-or-later
"""The compiled self-intersection search against brute force and an independent test.

Boxes: every pair of a set of random boxes of mixed sizes (some on integer coordinates,
so that some only touch) is compared by hand. Triangles: a soup of random triangles with
no shared corners is tested pair by pair with libigl's ``tri_tri_intersection_test_3d``
(Guigue-Devillers, an independent implementation); random triangles are in general
position, so contacts within the tolerance do not occur.
"""
import itertools

import numpy as np
import pytest

from core.self_intersection import box_pairs, face_boxes, find_self_intersections


def brute_force_box_pairs(lo, hi, among=None):
    """The set of overlapping pairs (i < j, touching counts), pair by pair."""
    found = set()
    for i, j in itertools.combinations(range(len(lo)), 2):
        if among is not None and not (among[i] or among[j]):
            continue
        if np.all(lo[i] <= hi[j]) and np.all(lo[j] <= hi[i]):
            found.add((i, j))
    return found


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_box_pairs_are_every_overlapping_pair_once(seed):
    rng = np.random.default_rng(seed)
    count = 301  # not a multiple of the tree's leaf size, nor a power of two
    lo = np.floor(rng.random((count, 3)) * 20.0)
    size = np.where(rng.random((count, 1)) < 0.1, 8.0, 2.0) * np.floor(rng.random((count, 3)) * 2 + 1)
    hi = lo + size
    lo[:100] = rng.random((100, 3)) * 20.0  # a third off the integer grid
    hi[:100] = lo[:100] + rng.random((100, 3)) * 3.0
    pairs = box_pairs(lo, hi)
    assert (pairs[:, 0] < pairs[:, 1]).all()
    assert len({tuple(p) for p in pairs}) == len(pairs), "a pair is reported twice"
    expected = brute_force_box_pairs(lo, hi)
    assert {tuple(p) for p in pairs} == expected
    touching = sum(1 for i, j in expected if np.any(lo[i] == hi[j]) or np.any(lo[j] == hi[i]))
    assert touching > 10, "the set has boxes that only touch"
    among = rng.random(count) < 0.1
    marked_pairs = box_pairs(lo, hi, among)
    assert {tuple(p) for p in marked_pairs} == brute_force_box_pairs(lo, hi, among)
    np.testing.assert_array_equal(box_pairs(lo, hi), pairs)  # the same boxes, the same rows


def test_box_pairs_of_no_boxes_and_of_one():
    assert box_pairs(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0, 2)
    assert box_pairs(np.zeros((1, 3)), np.ones((1, 3))).shape == (0, 2)


def test_crossings_of_a_triangle_soup_match_an_independent_test():
    igl = pytest.importorskip("igl")
    rng = np.random.default_rng(5)
    count = 120
    centres = rng.random((count, 1, 3)) * 4.0
    V = (centres + rng.normal(scale=0.5, size=(count, 3, 3))).reshape(-1, 3)
    F = np.arange(3 * count).reshape(-1, 3)
    expected = set()
    for i, j in itertools.combinations(range(count), 2):
        a, b = V[F[i]], V[F[j]]
        hit = igl.tri_tri_intersection_test_3d(a[0][None], a[1][None], a[2][None],
                                               b[0][None], b[1][None], b[2][None])[0]
        if hit:
            expected.add((i, j))
    found = find_self_intersections(V, F)
    assert len(expected) > 50
    assert {tuple(p) for p in found} == expected
    np.testing.assert_array_equal(found, np.array(sorted(expected)))
    marked = np.zeros(count, dtype=bool)
    marked[:10] = True
    assert {tuple(p) for p in find_self_intersections(V, F, among=marked)} == {
        (i, j) for i, j in expected if i < 10}


def test_faces_sharing_a_corner_cross_and_faces_sharing_an_edge_do_not():
    """Two faces sharing a corner, the edge of one opposite that corner through the other:
    a crossing. Two faces sharing an edge, the second folded flat onto the first: not one
    (exactly coplanar overlaps are not reported, and such pairs are skipped)."""
    V = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, -1], [0.5, 0.5, 1]])
    F = np.array([[0, 1, 2], [0, 3, 4]])  # edge 3-4 passes through (0.5, 0.5, 0) on face 0
    np.testing.assert_array_equal(find_self_intersections(V, F), [[0, 1]])
    V[3:, :2] = [3.0, -1.0]  # face 1 now meets face 0's plane on a line through the
    # shared corner only, away from face 0
    assert len(find_self_intersections(V, F)) == 0
    V_folded = np.array([[0.0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, 0]])
    F_folded = np.array([[0, 1, 2], [0, 1, 3]])
    assert len(box_pairs(*face_boxes(V_folded[F_folded]))) == 1
    assert len(find_self_intersections(V_folded, F_folded)) == 0

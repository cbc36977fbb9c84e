# SPDX-License-Identifier: LGPL-2.1-or-later
"""Keep a fitted limit surface from crossing itself.

A least-squares fit of a coarse cage to a thin member pulls its two walls through each
other, and on paired-decimation cages some limit surfaces cross before any fit (quads
folded onto themselves at thin struts). Two remedies, both local:

* :func:`stiffen_until_clean` refits with the cage's smoothness term made ``UNTANGLE.stiffen``
  times stiffer at every base vertex that influences a crossing triangle, until the
  limit surface is clean (or ``UNTANGLE.stiffen_tries`` refits): the displacement field there
  follows its neighbours instead of the far wall. Where the plain fit pulled the cage's
  few crossings into many, the first or second refit is usually clean.
* :func:`hold_back_crossings` undoes a move towards its reference, only where the moved
  surface has a crossing that the reference does not have.

Crossings are the intersecting triangle pairs of the fine limit mesh
(:func:`core.self_intersection.find_self_intersections`).
"""
from dataclasses import dataclass

import numpy as np

from core.box_tree import face_boxes
from core.self_intersection import box_pairs, find_self_intersections
from core.tolerances import CONTACT


@dataclass(frozen=True)
class UntangleSettings:
    """Tuned constants of the crossing hold-back and the untangling refits."""

    stiffen: float = 10.0
    """Factor on the smoothness weight of the base vertices under a crossing, per refit."""
    stiffen_tries: int = 4
    """Most refits of :func:`stiffen_until_clean` (later refits do not lower the crossings
    further)."""
    progress: float = 0.05
    """Least fraction of the fewest crossing pairs so far that an untangling refit must take
    off for another while those fewest are more than ``tangled`` times the first fit's and
    more than ``few_crossings`` (:func:`stiffen_until_clean` from
    :func:`core.fitting.fit._untangled`). On creased cages of machined parts the refits do
    not untangle (the crossing pairs stay level or grow), so they stop after one to three
    refits with the fit kept so far; on a SIMP result whose crossings fall unevenly they go
    on."""
    tangled: float = 0.5
    """Fewest crossings so far, times the first fit's, at or below which the refits go on
    whatever they take off (a refit that removed most crossings may need one more to remove
    the rest)."""
    few_crossings: int = 20
    """Fewest crossing pairs at or below which the refits go on whatever they take off (a
    handful of crossings often goes with the next refit)."""
    halvings: int = 6
    """Rounds of halving the moves of the base vertices owning a crossing's corners, then as
    many of halving the moves of every base vertex influencing it, before those are held
    back completely (:func:`hold_back_crossings`)."""


UNTANGLE = UntangleSettings()
"""The settings this module runs with."""


@dataclass
class Untangled:
    """Outcome of :func:`stiffen_until_clean`.

    vertices : (n, 3) float64 the fit with the fewest crossings (the first clean one).
    crossings : int, intersecting triangle pairs of its fine limit mesh.
    stiffness : (n,) float64 the smoothness weights it was fitted with (ones: no refit).
    refits : int, refits run.
    counts : list of int, crossing pairs after the first fit and each refit.
    pairs : (crossings, 2) int64 the intersecting triangle pairs of its fine mesh.
    """

    vertices: np.ndarray
    crossings: int
    stiffness: np.ndarray
    refits: int
    counts: list
    pairs: np.ndarray


def crossing_pairs(mapping, triangles, vertices):
    """(k, 2) int64 intersecting triangle pairs of the fine mesh ``mapping @ vertices``
    (:func:`core.self_intersection.find_self_intersections`)."""
    return find_self_intersections(mapping @ vertices, triangles)


def count_crossings(mapping, triangles, vertices):
    """Intersecting triangle pairs of the fine mesh ``mapping @ vertices`` (int)."""
    return int(len(crossing_pairs(mapping, triangles, vertices)))


def influencing(pairs, mapping, triangles):
    """(k,) int64 base vertices with a non-zero weight on a corner of a crossing triangle.

    pairs : (p, 2) int64 crossing triangle pairs; mapping : (n_fine, n) sparse CSR;
    triangles : (t, 3) int64 fine triangles.
    """
    return np.unique(mapping[np.unique(triangles[pairs].reshape(-1))].indices)


def stiffen_until_clean(vertices, refit, mapping, triangles, tries=UNTANGLE.stiffen_tries,
                        pairs=None, progress=0.0):
    """Refit with a stiffer smoothness term under the crossings until nothing crosses.

    Parameters
    ----------
    vertices : (n, 3) float64 base vertices of the first fit (model units).
    refit : callable ``refit(stiffness, previous) -> (n, 3) vertices``, the same fit with
        the per-vertex smoothness weights ``stiffness`` ((n,) float64,
        :class:`core.fitting.best_fit.NormalEquations`), started from ``previous`` ((n, 3)
        float64, the fit before it, which still crosses itself).
    mapping : (n_fine, n) sparse CSR, fine limit points ``mapping @ V``.
    triangles : (t, 3) int64 fine triangles.
    tries : int >= 0, most refits.
    pairs : (k, 2) int64 or None, the crossing pairs of ``vertices``' fine mesh when they
        are known (:func:`crossing_pairs`).
    progress : float in [0, 1), the refits stop when one leaves more than ``1 - progress``
        times the fewest crossing pairs before it while those fewest are more than
        ``UNTANGLE.tangled`` times the first fit's and more than ``UNTANGLE.few_crossings`` (0: only
        ``tries``, a clean fit or a refit crossing at the same pairs as the one before stop
        them).

    Returns
    -------
    Untangled
    """
    stiffness = np.ones(mapping.shape[1])
    if pairs is None:
        pairs = crossing_pairs(mapping, triangles, vertices)
    counts = [int(len(pairs))]
    best = Untangled(vertices, counts[0], stiffness.copy(), 0, counts, pairs)
    for refit_number in range(1, tries + 1):
        if not len(pairs):
            break
        stiffness[influencing(pairs, mapping, triangles)] *= UNTANGLE.stiffen
        vertices = refit(stiffness, vertices)
        previous, pairs = pairs, crossing_pairs(mapping, triangles, vertices)
        counts.append(int(len(pairs)))
        fewest = best.crossings
        if len(pairs) < fewest:
            best = Untangled(vertices, int(len(pairs)), stiffness.copy(), 0, counts, pairs)
        if np.array_equal(pairs, previous):
            break  # stiffer there, the same triangles cross: no untangling left to find
        tangled = max(counts[0] * UNTANGLE.tangled, UNTANGLE.few_crossings)
        if progress and tangled < fewest < len(pairs) / (1.0 - progress):
            break  # far from clean, and stiffening no longer takes crossings off
    best.refits = len(counts) - 1
    return best


def hold_back_crossings(reference, moved, mapping, triangles, clean=True, moved_pairs=None,
                        halvings=UNTANGLE.halvings):
    """Undo a move where it makes the limit surface cross itself, and only there.

    While the fine mesh ``mapping @ W`` of ``W = reference + t (moved - reference)`` has
    an intersecting triangle pair that the reference's fine mesh does not have, the move
    fraction ``t`` of the base vertex with the largest weight in each such triangle
    corner's row of ``mapping`` is halved; after ``halvings`` such rounds the fraction of
    every base vertex influencing a still new crossing is halved, ``halvings`` rounds more,
    and after those every such vertex keeps its reference position, round after round
    until nothing new crosses (a held-back region can cross a moved neighbour, so one
    round that undid everything would lose the whole move).
    When no owner of a new crossing moves, the influencing vertices' halvings start at
    once. Crossings that survive the owners' halvings are where the reference's walls nearly
    touch and a neighbour's move alone still pushes one through the other; halving the
    whole influencing region together keeps part of its move, so less of the target's
    volume is left outside than when the region keeps its reference position.
    Thin members that the cage cannot resolve are where a fit pulls the two walls through
    each other; elsewhere the move is kept whole (halving every influencing vertex from the
    start would hold back many more base vertices and leave the fit farther from the
    target). Only the triangles that the moving base vertices influence
    are tested in the first round, and those that the halved ones influence in the later
    rounds (:func:`_crossings_after`): a pair of triangles that do not move keeps the
    reference's answer. The face pairs whose boxes may overlap at any fractions are found
    once (:func:`_swept_pairs`) and each round tests only those of them that overlap now.

    Parameters
    ----------
    reference : (n, 3) float64 base vertices before the move.
    moved : (n, 3) float64 base vertices after the move.
    mapping : (n_fine, n) sparse CSR, fine points ``mapping @ V``.
    triangles : (t, 3) int64 fine triangles.
    clean : bool, the reference's fine mesh is known not to cross itself (False: its
        crossing pairs are found and kept allowed, so the result crosses no more than it).
    moved_pairs : (k, 2) int64 or None, the crossing pairs of the moved fine mesh when they
        are known (:attr:`Untangled.pairs`): they stand for those of the first round's
        ``reference + (moved - reference)``, which is ``moved`` to rounding.
    halvings : int >= 0, rounds of halving of each kind (owners, then influencing
        vertices) before the influencing vertices are held back completely.

    Returns
    -------
    vertices : (n, 3) float64, ``moved`` where it adds no crossing; its crossing pairs are
        a subset of the reference's.
    held : int, base vertices whose move was cut (0 when ``moved`` adds no crossing).
    crossings : int, intersecting triangle pairs of the returned fine mesh.
    """
    allowed = (np.zeros((0, 2), dtype=np.int64) if clean
               else crossing_pairs(mapping, triangles, reference))
    fraction = np.ones(len(moved))
    moving = (moved != reference).any(axis=1)
    if not moving.any():
        return reference.copy(), 0, int(len(allowed))
    # the reference's pairs, of which only those near a moving vertex can change
    pairs, changed, halving, candidates = allowed, moving, 0, None
    while True:
        # a vertex not held back is ``moved`` bit for bit (the callers tell held-back
        # vertices by comparing), not ``reference + (moved - reference)``
        W = np.where((fraction == 1)[:, None], moved,
                     reference + fraction[:, None] * (moved - reference))
        if halving == 0 and moved_pairs is not None:
            pairs = moved_pairs
        else:
            if candidates is None:
                candidates = _swept_pairs(reference, moved, mapping, triangles)
            pairs = _crossings_after(mapping @ W, triangles, pairs, mapping, changed,
                                     candidates)
        new = pairs[~_rows_in(pairs, allowed)]
        if not len(new):
            return W, int(((fraction < 1) & moving).sum()), int(len(pairs))
        before = fraction.copy()
        owner = None
        if halving < halvings:
            fine = np.unique(triangles[new].reshape(-1))
            owner = np.unique(np.asarray(abs(mapping[fine]).argmax(axis=1)).ravel())
        if owner is not None and moving[owner].any():
            fraction[owner] *= 0.5
        elif halving < 2 * halvings:
            # no owner moves (a neighbour's move carries the corners through): on to the
            # influencing vertices at once
            halving = max(halving, halvings)
            fraction[influencing(new, mapping, triangles)] *= 0.5
        else:
            fraction[influencing(new, mapping, triangles)] = 0.0
        halving += 1
        changed = (fraction != before) & moving
        if not changed.any():
            return reference.copy(), int(moving.sum()), int(len(allowed))


def _crossings_after(X, triangles, pairs, mapping, changed, candidates):
    """(k, 2) int64 crossing triangle pairs of the fine mesh ``X`` ((n_fine, 3)).

    ``pairs`` ((p, 2) int64) are those found before the base vertices marked in
    ``changed`` ((n,) bool) moved; only the triangles these base vertices influence
    through ``mapping`` are tested again, the other pairs are kept. ``candidates``
    ((c, 2) int64, :func:`_swept_pairs`) hold every triangle pair whose boxes overlap.
    """
    # scipy's abs sorts the rows of an unsorted CSR matrix in place, so the fit's limit map is
    # sorted by the first such call and every later product with it rounds that way, which
    # keeps the fit's results reproducible
    fine = np.asarray(abs(mapping) @ changed.astype(np.float64)).ravel() > 0
    moved = fine[triangles].any(axis=1)
    kept = pairs[~moved[pairs].any(axis=1)]
    found = np.concatenate([kept, find_self_intersections(X, triangles, among=moved,
                                                          candidates=candidates)])
    return found[np.lexsort((found[:, 1], found[:, 0]))]


def _swept_pairs(reference, moved, mapping, triangles):
    """(c, 2) int64 the fine triangle pairs that may cross on the way from ``reference`` to
    ``moved`` ((n, 3) base vertices): those with a triangle that a moving base vertex
    influences whose bounding boxes overlap for some base vertices
    ``reference + t (moved - reference)``, ``t`` in [0, 1] per vertex.

    A fine point ``sum_v w_v (r_v + t_v d_v)`` stays within ``sum_v min(0, w_v d_v)`` and
    ``sum_v max(0, w_v d_v)`` of its reference position, axis by axis; the boxes of those
    ranges are widened by ``core.tolerances.CONTACT`` of the largest coordinate for the
    rounding of the points as the fit computes them, so the pairs include every pair that
    overlaps at any ``t`` (:func:`core.self_intersection.box_pairs`). The terms are summed
    from ``mapping``'s arrays, not by scipy's ``maximum``, which sorts the rows of the
    matrix it is called on in place (every later product with it would round differently). A
    pair of triangles that no moving vertex influences keeps its answer
    (:func:`_crossings_after`), so it is not kept: a hold-back's rounds test each of the
    pairs again. Pairs sharing an edge are kept (a few per triangle among millions of pairs):
    the narrow phase never reports them (:mod:`core.self_intersection`), and sorting them
    out here would cost more than testing them.
    """
    moving = (moved != reference).any(axis=1)
    # only the entries of moving vertices: the others' terms are zeros, whose sums leave
    # every row's sum as it is
    entries = np.flatnonzero(moving[mapping.indices])
    rows = np.searchsorted(mapping.indptr, entries, side="right") - 1
    terms = mapping.data[entries, None] * (moved - reference)[mapping.indices[entries]]
    X = mapping @ reference
    low, high = X.copy(), X.copy()
    for axis in range(3):
        low[:, axis] += np.bincount(rows, np.minimum(terms[:, axis], 0.0), len(X))
        high[:, axis] += np.bincount(rows, np.maximum(terms[:, axis], 0.0), len(X))
    slack = CONTACT * max(float(np.abs(low).max()), float(np.abs(high).max()), 1e-300)
    # from the matrix's arrays too (abs would sort it in place, see _crossings_after)
    moving_fine = np.bincount(rows, mapping.data[entries] != 0, len(X)) > 0
    return box_pairs(face_boxes(low[triangles])[0] - slack, face_boxes(high[triangles])[1] + slack,
                     among=moving_fine[triangles].any(axis=1))


def _rows_in(pairs, allowed):
    """(p,) bool: each row of ``pairs`` ((p, 2) int64) is a row of ``allowed``."""
    if not len(allowed) or not len(pairs):
        return np.zeros(len(pairs), dtype=bool)
    width = int(max(pairs.max(), allowed.max())) + 1
    return np.isin(pairs[:, 0] * width + pairs[:, 1], allowed[:, 0] * width + allowed[:, 1])

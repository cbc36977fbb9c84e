# SPDX-License-Identifier: LGPL-2.1-or-later
"""Move the base vertices under the fine limit points left outside the target inwards,
only as far as the limit surface stays clean.

In the inside fit (:func:`core.fitting.fit.fit_base_mesh`) the volume left outside lies
where the relaxed gradient projection's moves crossed the limit surface through itself
and were held back towards its start, which lies partly outside. :func:`nudge_inside`
moves, per round, the base vertex with the largest weight on each outside fine point by
that point's depth along the target's inward normal (the mean over the points it
carries), and holds the move back where it adds a crossing
(:func:`core.fitting.crossings.hold_back_crossings`). Only base vertices carrying an
outside point move (the fit passes only the held-back ones), so the rest of the fit keeps
its distances (the drift of a whole-surface pull inside is what ruled that out).

Where the wall behind an outside point is near (a thin plate's other side), moving the
near wall alone crosses it: the later rounds move that far wall's base vertices along
too, where it has room inside the target, so the thin section moves inwards as a whole.
"""
from dataclasses import dataclass

import numpy as np

from core.fitting.crossings import hold_back_crossings
from core.fitting.responses import InsideBounds, vertex_normals
from core.target_surface import TargetSurface
from core.tolerances import CONTACT


@dataclass(frozen=True)
class NudgeSettings:
    """Tuned constants of :func:`nudge_inside`."""

    rounds: int = 4
    """Rounds of each kind of :func:`nudge_inside`: near walls alone, then with far walls
    (the owner moves stall after about four rounds)."""
    halvings: int = 2
    """Halvings of each kind in a round's hold-back
    (:func:`core.fitting.crossings.hold_back_crossings`): a round moves by a point's depth, and
    what a quarter of that does not bring in, the next round tries again (more halvings
    bring in hardly more volume, at twice the nudge's CPU time)."""
    progress: float = 0.01
    """Least fraction of the summed outside depth a round must take off for another round of
    its kind (the third and later rounds of a kind take off a negligible share of the
    target's volume, so stopping then costs almost nothing and saves half the rounds)."""
    carry_reach: float = 8.0
    """Depths of the outside point along its inward normal within which a far wall it hits
    moves along (a shorter reach leaves more of the target's volume outside)."""
    carry_room: float = 0.5
    """Fraction of the depth every corner of the hit triangle must lie inside the target for
    the far wall to move along (so carrying it does not push the far wall out of the
    target's other side)."""


NUDGE = NudgeSettings()
"""The settings this module runs with."""


def nudge_inside(vertices, mapping, triangles, target, movable=None, rounds=NUDGE.rounds):
    """Move the base vertices that carry fine limit points outside the target inwards.

    Parameters
    ----------
    vertices : (n, 3) float64 base vertices (model units) whose fine limit mesh does not
        cross itself.
    mapping : (n_fine, n) sparse CSR, fine limit points ``mapping @ V``.
    triangles : (t, 3) int64 fine triangles.
    target : core.target_surface.TargetSurface
    movable : (n,) bool or None, the base vertices that may move (None: all); an outside
        point whose largest weight is on another vertex is left where it is.
    rounds : int >= 0, most rounds of each kind (near walls, then near and far walls); a
        kind stops early when its last round took less than ``NUDGE.progress`` off the
        summed depth of the outside points.

    Returns
    -------
    vertices : (n, 3) float64, their fine limit mesh still clean.
    moved : list of int, base vertices moved in each round run (after the hold-back).
    """
    V = np.array(vertices, dtype=np.float64)
    # the points a round's move left provably inside are not queried again
    known = InsideBounds(CONTACT * target.diagonal)
    moved = []
    for carry in (False, True):
        before = np.inf
        for _ in range(rounds):
            shift, depth = _shift(V, mapping, triangles, target, movable, carry, known)
            if shift is None:
                return V, moved
            if depth > (1.0 - NUDGE.progress) * before:
                break
            before = depth
            nudged, _, _ = hold_back_crossings(V, V + shift, mapping, triangles,
                                               halvings=NUDGE.halvings)
            changed = (nudged != V).any(axis=1)
            moved.append(int(changed.sum()))
            if not changed.any():
                break
            V = nudged
    return V, moved


def _shift(V, mapping, triangles, target, movable, carry, known):
    """Per base vertex the mean inward move of the outside points it carries.

    A point within ``core.tolerances.CONTACT`` of the diagonal outside the target is on it
    and not carried; the weight of a point in the mean ramps from 0 there to 1 at twice that
    depth, so the move is continuous in the points' positions. Some of the points a fit
    leaves outside lie on the target's surface to rounding (such as points of crease curves
    placed on the target's feature lines): counted as outside, each would change the count
    that divides the others' moves, and rounding decides which are.

    ``known`` (:class:`core.fitting.responses.InsideBounds`, kept over the rounds) skips the
    closest-point queries of the fine points proven inside since their last one; a far
    wall's corner is queried when its bound does not already prove the room the carry
    needs. The moves are those of querying every point.

    Returns
    -------
    shift : (n, 3) float64 the move (with ``carry`` also of the outside points whose far
        wall the vertex carries), or None when no outside point is left to a movable vertex.
    depth : float, summed depth of all fine points outside the target (model units).
    """
    X = mapping @ V
    query = known.undecided(X)
    near = known.closest(target, X, query)
    out = near.signed > 0
    outside = query[out]
    depth = near.signed[out]
    wanted = -depth[:, None] * near.mean_plane()[0][out]
    weight = np.clip(depth / (CONTACT * target.diagonal) - 1.0, 0.0, 1.0)
    owner = _owner(mapping, outside)
    if carry and len(outside):
        direction = -vertex_normals(X, triangles)[outside]
        hits = TargetSurface(X, triangles, "fitted surface").first_exit(
            X[outside], direction, NUDGE.carry_reach * float(depth.max()))
        found = hits.face >= 0
        corners = triangles[hits.face[found]]
        room = -NUDGE.carry_room * depth[found]
        # the corners' bounds decide the room where they are below it; the corners of the
        # other walls that were not queried this round are queried now
        undecided = (known.bound(X)[corners] >= room[:, None]).any(axis=1)
        unsure = np.setdiff1d(corners[undecided], query)
        known.closest(target, X, unsure)
        roomy = known.bound(X)[corners].max(axis=1) < room
        far = np.flatnonzero(found)[roomy & (hits.t[found] < NUDGE.carry_reach * depth[found])]
        owner = np.concatenate([owner, _owner(mapping, triangles[hits.face[far]].reshape(-1))])
        wanted = np.concatenate([wanted, np.repeat(wanted[far], 3, axis=0)])
        weight = np.concatenate([weight, np.repeat(weight[far], 3)])
    keep = weight > 0
    if movable is not None:
        keep &= movable[owner]
    owner, wanted, weight = owner[keep], wanted[keep], weight[keep]
    if not len(owner):
        return None, float(depth.sum())
    shift = np.zeros_like(V)
    np.add.at(shift, owner, wanted * weight[:, None])
    total = np.bincount(owner, weight, minlength=len(V))
    carries = total > 0
    shift[carries] /= total[carries, None]
    return shift, float(depth.sum())


def _owner(mapping, points):
    """(k,) int64 the base vertex with the largest weight on each fine point of ``points``."""
    return np.asarray(abs(mapping[points]).argmax(axis=1)).ravel()

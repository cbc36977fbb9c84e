# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quad-dominant base mesh without a polycube: decimate the target, pair its triangles.

The fallback of the base-mesh stage for labelings whose quantized layout cannot be built (turning
points a polycube cannot realise, chart polygons that overlap, layouts far over the face budget,
inverted faces). It needs no labeling, so it always gives a closed 2-manifold with the target's
genus and orientation:

1. QSlim (Garland & Heckbert, "Surface simplification using quadric error metrics", SIGGRAPH
   1997; libigl's ``igl.qslim``) collapses edges of the target, in quadric-error order, down to
   twice the face budget in triangles (:mod:`core.quadmesh.decimation.decimation`). Collapses that
   would change the topology are refused. :mod:`core.quadmesh.decimation.even_triangulation` then
   gives planar fans interior vertices and untangles folded triangles.
2. Blossom-Quad (Remacle et al., "Blossom-Quad: a non-uniform quadrilateral mesh generator using
   a minimum-cost perfect matching algorithm", IJNME 2012): every pair of triangles sharing an
   edge is a candidate quad, weighted by its corner angles and its flatness; a matching on the
   dual graph picks the pairs (greedy by weight, then augmenting paths towards a perfect
   matching, :func:`_match_pairs`, instead of the paper's exact minimum-cost perfect matching).
   The dual graph of a closed triangle surface is cubic and bridgeless, so a perfect matching
   exists (Petersen) and the result is all quads in practice; unmatched triangles stay
   triangles (Catmull-Clark and the export take mixed cages). Vertices with only two faces are
   merged away, and the vertices are moved onto the target.
3. Where the cage's limit surface faces away from the target, the vertices of those faces are
   moved off the target, towards a limit surface through their on-target positions
   (:mod:`core.quadmesh.limit_interpolation`), and faces still inverted are edited: a corner
   relaxed or a quad split (:mod:`core.quadmesh.local_repair`; both in the budget ladder
   only). Where the cage of the face budget still crosses itself or faces away (a thin strut
   with too few faces around it), the budget is decimated again by half-edge collapses in
   quadric-error order (:mod:`core.quadmesh.decimation.fold_free_decimation` without its
   normal rule), tightened around the faces whose limit surface crosses itself (the normal
   rule brought in there, one step more each round, :data:`TIGHTEN_ROUNDS`): more faces only
   where it crosses, so the cage keeps about the budget wherever the crossings are, and its
   face count follows the shape, not whether QSlim of one triangulation happened to leave the
   strut thick enough. Where that cage is flawed too, larger budgets within the allowed range
   are tried; where they all cross themselves, budgets beyond it (a solid needs a surface that
   does not), until more faces stop helping.
4. Where every budget's limit surface crosses itself (machined parts whose sharp steps the
   smooth limit rounds over a face's length), the ladder runs again on feature-preserving
   decimations (:mod:`core.quadmesh.decimation.feature_decimation`), evened out inside their planar
   regions without touching a feature edge
   (:func:`core.quadmesh.decimation.even_triangulation.even_creased_triangulation`; where that cage
   is flawed and the one of the decimation as it is is less so, the latter is kept, since evening
   out can itself make a cage cross): the target's sharp feature lines
   (:mod:`core.quadmesh.creases`) stay chains of their edges, which are never paired across, stay
   cage edges and are tagged as creases (``PolyMesh.creases``), and the cage with fewer crossings of
   the two ladders is kept. A target without a closed network of feature lines (a SIMP result's
   iso-surface) has nothing to crease and keeps its smooth cage (and its large targets are spared
   the pure-Python decimation, which takes about a minute on 150k triangles). Only there: a thin
   plate with holes that is clean without tags can have every creased cage within the budget rule
   cross itself, so tagging is not the default; the cages of every mesh whose smooth ladder ends
   clean stay bit-identical.
5. Where the cage kept still crosses itself, the ladder runs on fold-free decimations
   (:mod:`core.quadmesh.decimation.fold_free_decimation`: half-edge collapses that never make a
   triangle facing across the target's normals at its corners, so no triangle spans a thin
   strut or plate), and then, while its cage crosses itself, on decimations tightened
   around the crossing faces (more faces only there, up to ``over_budget_faces``); its cage
   is kept where it crosses itself less. Where QSlim folds most of its triangles at the
   budget across the target (:data:`QSLIM_FOLDED_SHARE`: many thin members of a high-genus
   TO result, a raw marching-cubes staircase among them), this ladder runs first and the
   others only when its cage still crosses itself.
6. The valences of the cage kept are cleaned up
   (:mod:`core.quadmesh.decimation.valence_cleanup`: edge rotations and vertex splits that lower
   a valence energy where the faces stay well shaped and near the target, at most
   :data:`VALENCE_FACE_SLACK` more faces; no diagonal collapses, whose cages fit thin struts
   badly), and the cleaned cage repaired as in step 3. Where it has more limit-surface
   crossings or inverted faces than the cage kept, the cleanup runs again with its flawed
   faces' vertices fixed (:data:`CLEANUP_RETRIES`), and at last the cage is kept as it was.
   The ladders judge the cages as the pairing leaves them: a cleaned cage can cross itself
   less, and ending a ladder on it would skip the creased cages that fit a machined part's
   sharp edges. A single budget asked for (no ladder) is cleaned without this check. A cage
   of a fold-free decimation (step 5) is kept as it is: its faces were placed so that none
   spans a thin member, and the re-paired faces of the cleanup span them again, so the inside
   fit leaves more of the volume outside round the members.
"""
from dataclasses import dataclass, replace

import numpy as np

from core.errors import InvalidMeshError
from core.mesh_topology import edge_faces
from core.quadmesh.creases import closed_network
from core.quadmesh.crossing_count import LEVELS as CROSSING_LEVELS, LimitCrossingCount
from core.quadmesh.decimation.decimation import Decimation
from core.quadmesh.decimation.even_triangulation import (even_creased_triangulation,
                                                         even_triangulation)
from core.quadmesh.decimation.feature_decimation import FeatureDecimation
from core.quadmesh.decimation.fold_free_decimation import FoldFreeDecimation, folded_share
from core.quadmesh.decimation.valence_cleanup import clean_valences
from core.quadmesh.limit_interpolation import unshrink_inverted
from core.quadmesh.local_repair import repair_inverted
from core.quadmesh.orientation import inverted_faces
from core.polymesh_checks import check_polymesh
from core.subdivision.catmull_clark import mesh_topology
from core.target_surface import TargetSurface
from core.types import PolyMesh

MIN_WEIGHT = 1e-3
"""Matching weight of the worst candidate quad (folded or degenerate): still pairable."""
LADDER_STEPS = 3
"""Larger budgets tried (evenly up to the largest allowed) when a cage's limit surface is
flawed."""
OVER_BUDGET_FACTORS = (1.5, 2.0, 3.0, 4.0, 6.0)
"""Budgets beyond the budget rule, as multiples of the face budget, tried while the limit surface
of every cage crosses itself. On SIMP results with thin perforated walls of high genus the
crossings end at 2 or 3 times the budget, on a very fine such surface at up to 6 times
(``benchmarks/unseen_bench.py --large``); on machined parts with small steps and counterbores
they grow with the budget: :data:`OVER_BUDGET_MISSES`."""
OVER_BUDGET_MISSES = 2
"""The budgets beyond the budget rule end after this many in a row whose cages are not less
flawed (crossing pairs plus inverted faces) than every smaller one: more faces do not unfold
that limit surface. The flaws fall unevenly on SIMP results (a budget with more flaws can be
followed by a clean one), so one miss is not enough; on machined parts whose flaws grow with
the budget two end the ladder after 2 of its 5 steps, where the limit surfaces of a machined part's
sharp steps cross themselves (Catmull-Clark without crease rules rounds them)."""


QSLIM_FOLDED_SHARE = 0.5
"""Where more than this share of QSlim's triangles at the budget face across the target
(:func:`core.quadmesh.decimation.fold_free_decimation.folded_share`), the fold-free ladder is tried
before QSlim's. Such a share comes of many thin members coarsely decimated (high-genus
lattice-like TO results), whose QSlim cages cross themselves at every budget; the targets
whose QSlim ladder ends clean fold well under half of them."""
VALENCE_FACE_SLACK = 0.05
"""The valence cleanup's vertex splits add at most this share of the paired cage's faces. Its
diagonal collapses are not used here (the face count may not fall): a collapse takes faces
from around a thin strut and moves its merged corners, and the least-squares fit of such a
cage crosses itself and is held back there, far from the target."""
CLEANUP_RETRIES = 2
"""Valence cleanups run again, with the vertices of the last one's flawed faces kept, while the
cleaned cage has more limit flaws than the paired cage as it is."""
TIGHTEN_ROUNDS = 4
"""Fold-free decimations tightened around the crossings of the cage kept, at most (each
raises the normal agreement asked of the triangles there by one step,
:data:`core.quadmesh.decimation.fold_free_decimation.TIGHTEN_STEP`); and the locally tightened
decimations of the face budget (module docstring, step 3)."""
NO_NORMAL_RULE = -1.0
"""Smallest normal cosine of the locally tightened decimation before it is tightened: no
collapse is refused for its normal (a half-edge QSlim)."""


@dataclass(frozen=True)
class PairedDecimation:
    """Result of :func:`paired_decimation_base_mesh`.

    mesh : PolyMesh, quads and leftover triangles, closed, 2-manifold, outward, its vertices
        on the target (where moving them there degenerates no face), except those of inverted
        faces moved off it (:mod:`core.quadmesh.limit_interpolation`) in a budget ladder.
    decimated_triangles : int, triangles of the QSlim result that were paired.
    quads, triangles : int, faces of each kind in ``mesh``.
    rounds : tuple of dicts, one per budget tried (``faces``, ``limit_crossings``,
        ``inverted_faces``, ``moved_vertices``: after the moves, ``edits``: local edits kept,
        :mod:`core.quadmesh.local_repair`; ``crease_edges`` in the rounds of the creased
        ladder, ``fold_free`` and ``tightened`` in those of the fold-free one); empty when
        only one budget was asked for.
    limit_crossings : int or None, self-crossing triangle pairs of the level-2 limit surface
        of ``mesh`` (None when only one budget was asked for: not counted).
    fold_free : bool, ``mesh`` comes of a fold-free decimation (module docstring, step 5).
    tightened : int, the rounds of tightening around crossing faces that decimation had (a
        fold-free or a locally tightened one, steps 5 and 3).
    valence_moves : int, the moves of the valence cleanup in ``mesh`` (step 6; 0 where the
        cage is kept as the ladders left it).
    """

    mesh: PolyMesh
    decimated_triangles: int
    quads: int
    triangles: int
    rounds: tuple = ()
    limit_crossings: int = None
    fold_free: bool = False
    tightened: int = 0
    valence_moves: int = 0


def _candidate_quads(vertices, faces):
    """Every pair of triangles sharing an edge as a quad, with its matching weight.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed, outward.

    Returns
    -------
    pairs : (e, 2) int64 the two triangles of every interior edge.
    quads : (e, 4) int64 the quad's corners, counter-clockwise seen from outside.
    weight : (e,) float64 in [MIN_WEIGHT, 1 + MIN_WEIGHT]: mean over the four corners of
        ``1 - |cos(angle)|`` (1 for right angles), times the cosine of the fold between the two
        triangles (0 when folded by 90 degrees or more).
    """
    edges, pairs = edge_faces(faces)
    first, second = faces[pairs[:, 0]], faces[pairs[:, 1]]
    # the first triangle as (apex, x, y) with the shared edge x -> y; the second's apex opposite
    is_edge = (first == edges[:, :1]) | (first == edges[:, 1:])
    apex_at = np.argmin(is_edge, axis=1)
    rows = np.arange(len(first))
    apex = first[rows, apex_at]
    x = first[rows, (apex_at + 1) % 3]
    y = first[rows, (apex_at + 2) % 3]
    other = second[(second != edges[:, :1]) & (second != edges[:, 1:])]
    quads = np.stack([apex, x, other, y], axis=1)
    P = vertices[quads]
    to_next = np.roll(P, -1, axis=1) - P
    to_prev = np.roll(P, 1, axis=1) - P
    cosine = np.einsum("qkj,qkj->qk", to_next, to_prev) / np.maximum(
        np.linalg.norm(to_next, axis=2) * np.linalg.norm(to_prev, axis=2), 1e-300)
    corner_quality = (1.0 - np.abs(cosine)).mean(axis=1)
    n_first = np.cross(P[:, 1] - P[:, 0], P[:, 3] - P[:, 0])
    n_second = np.cross(P[:, 3] - P[:, 2], P[:, 1] - P[:, 2])
    flat = np.einsum("qj,qj->q", n_first, n_second) / np.maximum(
        np.linalg.norm(n_first, axis=1) * np.linalg.norm(n_second, axis=1), 1e-300)
    weight = MIN_WEIGHT + corner_quality * np.clip(flat, 0.0, 1.0)
    return pairs, quads, weight


def _match_pairs(n_faces, pairs, weight):
    """(e,) bool candidate pairs chosen: heaviest first, then augmented towards perfect.

    A greedy matching in decreasing weight (ties by index, so deterministic) leaves a few
    triangles whose neighbours are all taken. Each of them then searches, breadth first, an
    augmenting path: alternately an unchosen and a chosen pair, ending at another unmatched
    triangle; flipping the path matches both ends. (Without Edmonds' blossom contraction an
    augmenting path through an odd cycle can be missed; such a triangle stays a triangle.)
    Linear in the faces per unmatched triangle, so a small fraction of a second for a few
    thousand triangles, where an exact maximum-weight blossom matching (``networkx``) takes
    seconds to minutes; its total weight comes close to the exact optimum's, and the meshes
    tried are matched perfectly (all quads).
    """
    mate = np.full(n_faces, -1, dtype=np.int64)
    via = np.full(n_faces, -1, dtype=np.int64)
    for index in np.argsort(-weight, kind="stable").tolist():
        a, b = pairs[index]
        if mate[a] < 0 and mate[b] < 0:
            mate[a], mate[b] = b, a
            via[a] = via[b] = index
    neighbours = [[] for _ in range(n_faces)]
    for index, (a, b) in enumerate(pairs.tolist()):
        neighbours[a].append((b, index))
        neighbours[b].append((a, index))
    for start in np.flatnonzero(mate < 0).tolist():
        if mate[start] >= 0:
            continue
        _augment(start, mate, via, neighbours)
    chosen = np.zeros(len(pairs), dtype=bool)
    chosen[via[via >= 0]] = True
    return chosen


def _augment(start, mate, via, neighbours):
    """Match ``start`` along one augmenting path found breadth first; False if none found."""
    parent = {start: (-1, -1)}  # outer face -> (previous outer face, pair index taken to it)
    queue = [start]
    for outer in queue:
        for inner, index in neighbours[outer]:
            if inner in parent or inner == mate[outer]:
                continue
            if mate[inner] < 0:
                # flip the path: inner-outer, then each outer's old mate with its parent
                a, b, pair = inner, outer, index
                while b >= 0:
                    previous, taken = parent[b]
                    old = mate[b]
                    mate[a], mate[b] = b, a
                    via[a] = via[b] = pair
                    a, b, pair = old, previous, taken
                return True
            other = int(mate[inner])
            if other in parent:
                continue
            parent[inner] = (-2, -2)  # reached, as the inner end of a chosen pair
            parent[other] = (outer, index)
            queue.append(other)
    return False


def paired_decimation_base_mesh(vertices, faces, target_faces, surface=None, max_faces=None,
                                over_budget_faces=None):
    """Quad-dominant base mesh of about ``target_faces`` faces (module docstring).

    With ``max_faces`` above ``target_faces``, larger budgets up to it are tried in
    :data:`LADDER_STEPS` steps until a mesh's limit surface neither crosses itself nor has
    inverted faces (:func:`limit_flaws`); a coarse cage of a thin strut folds its limit surface,
    and a few more faces along the strut unfold it. The first clean mesh is kept, else the one
    with the fewest flaws (the smaller on a tie). When every one of them crosses itself and
    ``over_budget_faces`` is larger, the budgets :data:`OVER_BUDGET_FACTORS` times
    ``target_faces`` (at most ``over_budget_faces``) are tried too, and the first whose limit
    surface does not cross itself is kept: a solid needs it, the face budget does not. They
    stop after :data:`OVER_BUDGET_MISSES` in a row that are not less flawed than all before.
    When the cage kept still crosses itself and the target has feature lines, the whole
    ladder runs again with crease tags (module docstring, step 4), and its cage is kept if it
    crosses itself less; then, or first, the fold-free ladder (step 5).

    Parameters
    ----------
    vertices : (n, 3) float64 target vertices; faces : (m, 3) int64 closed, outward 2-manifold.
    target_faces : int >= 6, faces wanted (the decimation keeps twice as many triangles).
    surface : TargetSurface of the target already built, or None (built here).
    max_faces : int or None, the largest budget tried (None: ``target_faces`` only).
    over_budget_faces : int or None, the largest budget tried beyond ``max_faces`` while
        the limit surface crosses itself (None: none).

    Returns
    -------
    PairedDecimation

    Raises
    ------
    InvalidMeshError when the decimation changed the genus (it refuses such collapses, so this
    means a defect in the input the intake did not catch).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if surface is None:
        surface = TargetSurface(vertices, faces)
    target_faces = int(target_faces)
    max_faces = int(max_faces or target_faces)
    decimation = Decimation(vertices, faces, coarse_triangles=2 * max(max_faces, target_faces))
    if len(_ladder(target_faces, max_faces)) == 1 and not over_budget_faces:
        return _cleaned(_paired_mesh(decimation, 2 * target_faces, surface), surface)[0]
    rounds = []
    fold_free_first = bool(over_budget_faces) and folded_share(
        vertices, faces, *decimation.triangles(2 * target_faces)) > QSLIM_FOLDED_SHARE
    best = None
    if fold_free_first:
        # QSlim folds most of its triangles across the members: its ladder is tried only
        # if this one's cage still crosses itself (each rung costs seconds on a fine target)
        best = _tightened_ladder(FoldFreeDecimation(vertices, faces), surface, target_faces,
                                 max_faces, over_budget_faces, rounds)
    if best is None or best[2]:
        qslim = _budget_ladder(decimation, surface, target_faces, max_faces,
                               over_budget_faces, rounds,
                               local=(vertices, faces) if over_budget_faces else None)
        best = qslim if best is None or qslim[2] < best[2] else best
    if best[2] and over_budget_faces:
        feature_decimation = FeatureDecimation(vertices, faces, surface)
        if len(feature_decimation.target_features):
            creased = _budget_ladder(feature_decimation, surface, target_faces, max_faces,
                                     over_budget_faces, rounds)
            if creased[2] < best[2]:
                best = creased
    if best[2] and over_budget_faces and not fold_free_first:
        fold_free = _tightened_ladder(FoldFreeDecimation(vertices, faces), surface,
                                      target_faces, max_faces, over_budget_faces, rounds)
        if fold_free[2] < best[2]:
            best = fold_free
    result, crossings = _cleaned_or_not(best[1], surface, best[2], best[0] - best[2])
    return replace(result, rounds=tuple(rounds), limit_crossings=int(crossings))


def _budget_ladder(decimation, surface, target_faces, max_faces, over_budget_faces, rounds,
                   local=None):
    """The budget ladder of :func:`paired_decimation_base_mesh`, of QSlim's decimations or
    with crease tags of the feature-preserving ones (a Decimation or FeatureDecimation);
    appends its rounds and returns ``(flaws, PairedDecimation, crossings, budget)`` of the
    cage kept. A budget whose decimation is one an earlier budget got (a feature-preserving
    decimation whose every collapse left was refused) would give the same cage again: it is
    not built, and beyond the budget rule it counts as a budget no less flawed. With
    ``local`` (the target's ``(vertices, faces)``), a flawed cage of the face budget is
    followed by the locally tightened decimations of that budget (:func:`_locally_tightened`)
    before any larger budget."""
    best = None
    ladder = _ladder(target_faces, max_faces)
    for budget, new in _repeats_marked(decimation, ladder):
        if not new:
            continue
        result, crossings, inverted = _flawed_mesh(decimation, budget, surface, rounds)
        if best is None or crossings + inverted < best[0]:
            best = (crossings + inverted, result, crossings, budget)
        if crossings + inverted == 0:
            break
        if local is not None and budget == ladder[0]:
            tightened = _locally_tightened(*local, surface, budget, ladder[-1], rounds)
            if tightened[0] < best[0]:
                best = tightened
            if best[0] == 0:
                break
    if best[2] and over_budget_faces:
        fewest, misses = best[0], 0
        for budget, new in _repeats_marked(decimation, _over_budgets(
                target_faces, max_faces, int(over_budget_faces)), ladder):
            if not new:
                misses += 1
                if misses == OVER_BUDGET_MISSES:
                    break
                continue
            result, crossings, inverted = _flawed_mesh(decimation, budget, surface, rounds)
            if not crossings:
                return (crossings + inverted, result, 0, budget)
            misses = 0 if crossings + inverted < fewest else misses + 1
            fewest = min(fewest, crossings + inverted)
            if misses == OVER_BUDGET_MISSES:
                break
    return best


def _tightened_ladder(decimation, surface, target_faces, max_faces, over_budget_faces,
                      rounds):
    """The budget ladder on a FoldFreeDecimation, then, while the cage kept crosses itself,
    decimations tightened around its crossings (:meth:`FoldFreeDecimation.tightened`: more
    faces only where the limit surface crosses itself), up to :data:`TIGHTEN_ROUNDS` and
    ``over_budget_faces`` faces; returns ``(flaws, PairedDecimation, crossings, budget)`` of
    the least flawed cage (the first clean one)."""
    best = _budget_ladder(decimation, surface, target_faces, max_faces, over_budget_faces,
                          rounds)
    budget = best[3]
    for _ in range(TIGHTEN_ROUNDS):
        if not best[2]:
            break
        mesh = best[1].mesh
        decimation = decimation.tightened(2 * budget, _crossing_corners(mesh))
        if decimation is None:
            break
        result, crossings, inverted = _flawed_mesh(decimation, budget, surface, rounds)
        if result.mesh.n_faces > max(over_budget_faces, max_faces):
            break
        if crossings < best[2] or (crossings == best[2] and crossings + inverted < best[0]):
            best = (crossings + inverted, result, crossings, budget)
    return best


def _locally_tightened(vertices, faces, surface, budget, max_faces, rounds):
    """Cages of ``budget`` from half-edge QSlim decimations of the target (``vertices``,
    ``faces``) without a normal rule, tightened around the faces whose limit surface crosses
    itself (:meth:`FoldFreeDecimation.tightened`), up to :data:`TIGHTEN_ROUNDS` times while
    it does; appends their rounds and returns ``(flaws, PairedDecimation, crossings,
    budget)`` of the least flawed one (the first clean one).

    The rounds end early where the cage has more than ``max_faces`` faces (the tightened
    regions refuse so many collapses that the decimation stops short of the budget: the
    crossings are everywhere, as on a machined part's sharp steps) or after
    :data:`OVER_BUDGET_MISSES` rounds in a row without fewer crossings than every round
    before."""
    decimation = FoldFreeDecimation(vertices, faces, min_normal_cosine=NO_NORMAL_RULE)
    best, fewest, misses = None, None, 0
    for _ in range(TIGHTEN_ROUNDS + 1):
        result, crossings, inverted = _flawed_mesh(decimation, budget, surface, rounds)
        if best is None or crossings + inverted < best[0]:
            best = (crossings + inverted, result, crossings, budget)
        if not crossings:
            break  # clean, or inverted faces left that the repairs of the round could not fix
        misses = 0 if fewest is None or crossings < fewest else misses + 1
        fewest = crossings if fewest is None else min(fewest, crossings)
        if result.mesh.n_faces > max_faces or misses == OVER_BUDGET_MISSES:
            break
        mesh = result.mesh
        decimation = decimation.tightened(2 * budget, _crossing_corners(mesh))
        if decimation is None:
            break
    return best


def _crossing_corners(mesh):
    """(k, 3) float64 the corners of the base faces of ``mesh`` whose level-``CROSSING_LEVELS``
    limit surface crosses itself (a corner once per face holding it)."""
    from core.subdivision.limit_crossings import limit_self_intersections

    _, base_faces, _ = limit_self_intersections(mesh, CROSSING_LEVELS)
    corners = np.concatenate([mesh.face_vertices[mesh.face_offsets[f]:mesh.face_offsets[f + 1]]
                              for f in np.unique(base_faces)])
    return mesh.vertices[corners]


def _repeats_marked(decimation, budgets, tried=()):
    """``(budget, new)`` for each of ``budgets``: ``new`` is False when its decimation (to
    twice as many triangles) is the cached result of an earlier one or of a budget in
    ``tried``, the same triangles."""
    seen = {id(decimation.triangles(2 * budget)[1]) for budget in tried}
    for budget in budgets:
        faces = decimation.triangles(2 * budget)[1]
        yield budget, id(faces) not in seen
        seen.add(id(faces))


def _flawed_mesh(decimation, budget, surface, rounds):
    """The paired mesh of one budget (with crease tags from a FeatureDecimation), its inverted faces
    unshrunk (:func:`core.quadmesh.limit_interpolation.unshrink_inverted`), those left edited
    where its limit surface does not cross itself
    (:func:`core.quadmesh.local_repair.repair_inverted`), and its :func:`limit_flaws`; appends
    its round (with ``crease_edges`` and ``evened`` when tagged). A FeatureDecimation's
    triangles are evened out first (:func:`even_creased_triangulation`); where that cage is
    flawed, the cage of the decimation as it is is built too, and the less flawed one kept
    (the evened one on a tie)."""
    creased = isinstance(decimation, FeatureDecimation)
    result, crossings, inverted, moved, edits = _repaired(
        _paired_mesh(decimation, 2 * budget, surface), surface)
    evened, evened_flaws = creased, crossings + inverted
    if creased and evened_flaws:
        plain = _repaired(_paired_mesh(decimation, 2 * budget, surface, even=False), surface)
        if plain[1] + plain[2] < evened_flaws:
            (result, crossings, inverted, moved, edits), evened = plain, False
    rounds.append({"faces": int(result.mesh.n_faces), "limit_crossings": crossings,
                   "inverted_faces": inverted, "moved_vertices": moved, "edits": edits,
                   **({"crease_edges": int(result.mesh.n_creases), "evened": evened,
                       "evened_flaws": int(evened_flaws)} if creased else {}),
                   **({"fold_free": result.fold_free, "tightened": result.tightened}
                      if isinstance(decimation, FoldFreeDecimation) else {})})
    return result, crossings, inverted


def _cleaned(result, surface, fixed=()):
    """``(result, origin)``: ``result`` (a PairedDecimation) with its cage's valences cleaned
    (:func:`core.quadmesh.decimation.valence_cleanup.clean_valences`: edge rotations and
    vertex splits, up to :data:`VALENCE_FACE_SLACK` more faces; the vertices ``fixed`` kept),
    and the paired cage's vertex each vertex of the cleaned one comes from."""
    mesh = result.mesh
    cleanup = clean_valences(mesh, surface, mesh.n_faces,
                             int((1 + VALENCE_FACE_SLACK) * mesh.n_faces), fixed)
    sizes = cleanup.mesh.face_sizes
    return replace(result, mesh=cleanup.mesh, quads=int((sizes == 4).sum()),
                   triangles=int((sizes == 3).sum()),
                   valence_moves=cleanup.rotations + cleanup.collapses + cleanup.splits), \
        cleanup.origin


def _cleaned_or_not(result, surface, crossings, inverted):
    """``(result, crossings)``: the cage kept by the ladders (``result``, with its limit
    flaws ``crossings`` and ``inverted``) with its valences cleaned (:func:`_cleaned`) and
    repaired (:func:`_repaired`), where that has no more self-crossings of its limit surface
    and no more inverted faces; else the cleanup runs again with the vertices of the cleaned
    cage's flawed faces, and their neighbours, kept as they are (:data:`CLEANUP_RETRIES`
    times at most), and at last ``result`` is kept as it is. The ladders judge the cages as
    the pairing leaves them, so the cleanup changes no budget or route they take. A cage of a
    fold-free decimation is kept as it is (module docstring, step 6)."""
    if result.fold_free:
        return result, crossings
    fixed = set()
    for _ in range(CLEANUP_RETRIES + 1):
        cleaned, origin = _cleaned(result, surface, sorted(fixed))
        repaired, cleaned_crossings, cleaned_inverted, _, _ = _repaired(cleaned, surface)
        if cleaned_crossings <= crossings and cleaned_inverted <= inverted:
            return repaired, cleaned_crossings
        flawed = _flawed_faces(cleaned.mesh, surface)
        if not len(flawed):
            break  # flawed only after the repairs: nothing to keep fixed
        corners = np.unique(origin[np.concatenate(
            [cleaned.mesh.face_vertices[cleaned.mesh.face_offsets[f]:
                                        cleaned.mesh.face_offsets[f + 1]] for f in flawed])])
        fixed.update(_with_neighbours(result.mesh, corners).tolist())
    return result, crossings


def _flawed_faces(mesh, surface):
    """(k,) int64 faces of ``mesh`` that are inverted or hold a self-crossing of its
    level-``CROSSING_LEVELS`` limit surface."""
    from core.subdivision.limit_crossings import limit_self_intersections

    inverted = np.flatnonzero(inverted_faces(mesh, surface.vertices, surface.faces, surface))
    _, base_faces, _ = limit_self_intersections(mesh, CROSSING_LEVELS)
    return np.union1d(inverted, base_faces).astype(np.int64)


def _with_neighbours(mesh, vertices):
    """(k,) int64 ``vertices`` and the vertices sharing a face with them, in ``mesh``."""
    face_of_corner = np.repeat(np.arange(mesh.n_faces), mesh.face_sizes)
    faces = np.unique(face_of_corner[np.isin(mesh.face_vertices, vertices)])
    return np.unique(mesh.face_vertices[np.isin(face_of_corner, faces)])


def _repaired(result, surface):
    """``(result, crossings, inverted, moved, edits)``: :func:`_flawed_mesh`'s unshrinking
    and edits of one paired mesh."""
    count_crossings = LimitCrossingCount(result.mesh)
    crossings = count_crossings.crossings
    inverted = int(inverted_faces(result.mesh, surface.vertices, surface.faces, surface).sum())
    mesh, crossings, inverted, moved = unshrink_inverted(result.mesh, surface, crossings,
                                                         inverted, count_crossings)
    edits = 0
    if not crossings:
        # a cage whose limit surface crosses itself is refused or outranked by one that does
        # not, whatever its inverted faces: the edits would only cost time (several edits
        # per budget on a machined part)
        mesh, crossings, inverted, edits = repair_inverted(mesh, surface, crossings, inverted,
                                                           count_crossings)
    sizes = mesh.face_sizes
    result = replace(result, mesh=mesh, quads=int((sizes == 4).sum()),
                     triangles=int((sizes == 3).sum()))
    return result, crossings, inverted, moved, edits


def _over_budgets(target_faces, max_faces, over_budget_faces):
    """Budgets beyond ``max_faces``: :data:`OVER_BUDGET_FACTORS` times ``target_faces``, the
    last of them cut to ``over_budget_faces``."""
    budgets = []
    for factor in OVER_BUDGET_FACTORS:
        budget = min(int(round(factor * target_faces)), over_budget_faces)
        if budget > max(max_faces, budgets[-1] if budgets else 0):
            budgets.append(budget)
    return budgets


def _ladder(target_faces, max_faces):
    """Budgets from ``target_faces`` to ``max(max_faces, target_faces)`` in even steps."""
    if max_faces <= target_faces:
        return [target_faces]
    return sorted({int(round(b)) for b in np.linspace(target_faces, max_faces,
                                                      LADDER_STEPS + 1)})


def limit_flaws(mesh, surface):
    """Self-crossing triangle pairs of the level-2 limit surface, and inverted faces.

    mesh : PolyMesh base mesh; surface : TargetSurface of its target. Returns two ints
    (``core.subdivision.limit_crossings.limit_self_intersections`` and
    :func:`core.quadmesh.orientation.inverted_faces`).
    """
    from core.subdivision.limit_crossings import count_limit_self_intersections

    return (count_limit_self_intersections(mesh, 2),
            int(inverted_faces(mesh, surface.vertices, surface.faces, surface).sum()))


def _paired_mesh(decimation, count, surface, even=True):
    """Decimate to ``count`` triangles, pair, merge and project (module docstring): QSlim's
    result (a Decimation) evened out first; a FeatureDecimation's feature edges become crease
    edges and are never paired across, its triangles evened out first unless ``even`` is
    False."""
    if isinstance(decimation, FoldFreeDecimation):
        # its triangles already agree with the target's normals: evening them out would
        # move vertices off the target's vertices and can fold them again
        decimated_v, decimated_f = decimation.triangles(count)
        creases = None
    elif isinstance(decimation, FeatureDecimation) and not even:
        decimated_v, decimated_f, creases = decimation.triangles(count)
    elif isinstance(decimation, FeatureDecimation):
        decimated_v, decimated_f, creases = even_creased_triangulation(decimation, count,
                                                                       surface)
    else:
        decimated_v, decimated_f = even_triangulation(*decimation.triangles(count), surface)
        creases = None
    pairs, quads, weight = _candidate_quads(decimated_v, decimated_f)
    if creases is not None and len(creases):
        # a quad bent over a crease would hide it inside the quad: never pair across one
        across = _pair_keys(quads[:, 1], quads[:, 3], len(decimated_v))
        allowed = ~np.isin(across, _pair_keys(creases[:, 0], creases[:, 1], len(decimated_v)))
        # nor into a quad whose corner between two of its crease edges is reflex
        allowed &= ~_rim_folds(decimated_v, quads, creases)
        pairs, quads, weight = pairs[allowed], quads[allowed], weight[allowed]
    chosen = _match_pairs(len(decimated_f), pairs, weight)
    paired = np.zeros(len(decimated_f), dtype=bool)
    paired[pairs[chosen].reshape(-1)] = True
    kept = decimated_f[~paired]
    face_list = _merge_valence_two([list(q) for q in quads[chosen]] + [list(t) for t in kept],
                                   () if creases is None else set(creases.reshape(-1).tolist()))
    used = np.unique(np.concatenate(face_list))
    renumber = np.full(len(decimated_v), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    mesh = PolyMesh.from_faces(decimated_v[used], [renumber[f] for f in face_list])
    if creases is not None:
        mesh = replace(mesh, creases=_kept_creases(mesh, renumber[creases]))
    mesh = _projected_on_target(mesh, surface)
    sizes = mesh.face_sizes
    half_edge = isinstance(decimation, FoldFreeDecimation)
    return PairedDecimation(mesh, int(len(decimated_f)), int((sizes == 4).sum()),
                            int((sizes == 3).sum()), fold_free=half_edge and decimation.fold_free,
                            tightened=decimation.tightenings if half_edge else 0)


def _rim_folds(vertices, quads, creases):
    """(q,) bool: candidate quads ((q, 4) int64 corners) with a reflex corner between two of
    their own crease edges (``creases``, (c, 2) int64 vertex pairs).

    Such a quad is two triangles of a fan round a convex feature loop (a hole's rim of a
    flat face: three consecutive rim vertices and the fan's far apex, the rim corner well
    above 180 degrees). When the fit moves the rim out so that its crease
    curve follows the hole (:mod:`core.fitting.crease_curves`), the quad's limit patch folds
    over itself next to that corner, and the crossing hold-back keeps the rim in, leaving
    part of the target's volume outside. Without such quads (the fans' triangles stay
    triangles) fewer crease vertices are held back and much less volume stays outside, for
    a few more faces. Refusing every non-convex quad, or every one with its reflex corner on a
    crease vertex, costs many more quads for no gain; refusing only the sharpest reflex
    corners keeps some of the folds."""
    P = vertices[quads]
    normal = np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 1])  # across the diagonals
    turn = np.einsum("qkj,qj->qk", np.cross(P - np.roll(P, 1, axis=1),
                                            np.roll(P, -1, axis=1) - P), normal)
    n = len(vertices)
    # side[:, k]: the quad's edge from corner k to corner k + 1 is a crease edge
    side = np.isin(_pair_keys(quads, np.roll(quads, -1, axis=1), n),
                   _pair_keys(creases[:, 0], creases[:, 1], n))
    return ((turn < 0) & side & np.roll(side, 1, axis=1)).any(axis=1)


def _pair_keys(a, b, n):
    """(p,) int64 key of the unordered vertex pairs ``(a, b)`` of a mesh of ``n`` vertices."""
    return np.minimum(a, b) * n + np.maximum(a, b)


def _kept_creases(mesh, creases):
    """The crease pairs ((c, 2) int64, -1 for removed vertices) still edges of ``mesh``
    (merging vertices of two faces removes a few), as a closed network
    (:func:`core.quadmesh.creases.closed_network`), or None."""
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    kept = creases[(creases >= 0).all(axis=1)]
    return closed_network(kept[topo.edge_index(kept[:, 0], kept[:, 1]) >= 0],
                          len(mesh.vertices))


def _projected_on_target(mesh, surface):
    """``mesh`` with its vertices moved to their closest points on the target ``surface``
    (QSlim places them off it by up to its quadric error); unchanged if that degenerates a
    face."""
    projected = replace(mesh, vertices=surface.nearest(mesh.vertices).point)
    try:
        check_polymesh(projected)
    except InvalidMeshError:
        return mesh
    return projected


def _merge_valence_two(faces, fixed=()):
    """Remove vertices with two faces: two quads around one merge into one quad.

    A vertex ``v`` between the quads ``(a, v, b, c)`` and ``(b, v, a, d)`` is a corner of
    180-degree-or-worse angles on both and gives Catmull-Clark a pinched limit surface; their
    union without ``v`` is the quad ``(a, d, b, c)``. Merging can leave ``a`` or ``b`` with two
    faces, so it repeats until none is left. Vertices with two faces of which one is a
    triangle (rare) are kept.

    faces : list of vertex-index lists (quads and triangles), outward.
    fixed : collection of vertices never removed (those on crease edges: the merged quad would
        hide the crease in its diagonal).

    Returns the new list.
    """
    faces = [list(f) for f in faces]
    while True:
        incident = {}
        for index, face in enumerate(faces):
            for v in face:
                incident.setdefault(v, []).append(index)
        merged = set()
        for v, around in sorted(incident.items()):
            if len(around) != 2 or merged.intersection(around) or v in fixed:
                continue
            first, second = (faces[i] for i in around)
            if len(first) != 4 or len(second) != 4:
                continue
            k = first.index(v)
            a, b, c = first[k - 1], first[(k + 1) % 4], first[(k + 2) % 4]
            j = second.index(v)
            if second[j - 1] != b or second[(j + 1) % 4] != a:
                continue
            d = second[(j + 2) % 4]
            if d == c:
                continue  # two quads on the same four corners: a closed pillow, leave it
            faces[around[0]] = [a, d, b, c]
            faces[around[1]] = None
            merged.update(around)
        if not merged:
            return faces
        faces = [f for f in faces if f is not None]

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Side directions that make every chart a rectilinear polygon (turning number rule).

Walking a chart's boundary loop with the chart on the left (seen from outside), each corner
turns left (+1), right (-1) or goes straight (0) in the chart's plane, from the directions of
the two sides that meet there. A rectilinear polygon turns by exactly +4 around its outer loop
and -4 around each hole; a reversal (two consecutive sides along one axis in opposite
directions) is impossible. Side directions measured on the target can break this where a short
side zig-zags (noisy TO surfaces, turning points). :func:`make_loops_rectilinear` flips the
fewest measured side directions, weighted by their measured extent, so that every loop obeys
the rule: a small mixed-integer program (one binary per side direction, one per pair of
consecutive sides for the product of their flips, one per loop for outer/hole).

Proving that program infeasible can take HiGHS many branch-and-bound nodes where deciding a
feasible one takes a few at most. The program is therefore solved within a few nodes first;
when that does not decide it, the programs of single charts with their neighbours, each a
relaxation of the whole, are tried for a contradiction before the full search
(:func:`_local_contradiction`). Both steps are deterministic and change no answer: a feasible
program closed within those nodes has the optimum of the full search, and an infeasible
relaxation proves what the full search would. When the program is a stricter copy of one known
to have a solution (fewer collapsible sides), only the neighbourhoods holding a side that lost
its freedom can contradict, and they are tried first, before the first solve.
"""
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint

from core.errors import InternalError, LabelingError, OTHER_PARTS
from core.quadmesh.polycube.milp_solve import NODE_LIMIT, solve_feasibility, solve_milp

AXES = np.eye(3)
DISAGREEMENT_WEIGHT = 2.0
"""Cost of giving a side different directions in its two charts, relative to its measured
extent (flipping it in both charts costs the extent once): the charts still close and glue,
but the layout stops being a polycube there."""
CLOSURE_BOUND = 1000.0
"""Largest side length (relative to the shortest, 1) in the closure check."""
ROOT_NODES = 16
"""Nodes of the first solve of the whole program. The programs met in practice that have a
solution close within a few nodes (those of labelings with hundreds of charts seldom at the
root itself, and checking every neighbourhood instead costs several times the search); one
that does not (and has no solution found yet) is first checked for a neighbourhood that cannot
close (:func:`_local_contradiction`), which proves it infeasible in a fraction of the time a
full branch and bound takes to prove it."""
LIMIT_REACHED, INFEASIBLE = 1, 2
"""``scipy.optimize.milp`` statuses: a node (or other) limit reached; infeasible."""


class SideDirectionError(LabelingError):
    """No side directions make every chart a closed rectilinear polygon.

    ``collapsible``: (s,) bool the sides that were allowed length zero in the program that has
    no solution (so a caller that changes the labeling can judge the new one the same way).
    """

    def __init__(self, message, collapsible):
        super().__init__(message)
        self.collapsible = np.asarray(collapsible, dtype=bool)


def _loop_pairs(complex_, loops):
    """Every pair of consecutive references (each reference and the one after it, cyclically)
    of ``loops``, in the chart's plane with the current side directions.

    Parameters
    ----------
    complex_ : ChartComplex; loops : (l',) int64 loop indices.

    Returns
    -------
    keys, next_keys : (k,) int64 sign keys (``side * 2 + column``, as ``complex_.side_sign``'s
        flat layout) of each reference and of the one after it, loop by loop in walk order.
    turn : (k,) int64 turn at the corner between them about the chart's outward label normal
        (+1 left, -1 right, 0 straight).
    parallel : (k,) float64 dot product of their unit directions (-1: a reversal).
    loop_of : (k,) int64 index into ``loops`` of each reference.
    """
    loops = np.asarray(loops, dtype=np.int64)
    sizes = complex_.loop_offsets[loops + 1] - complex_.loop_offsets[loops]
    total = int(sizes.sum())
    first = np.repeat(np.cumsum(sizes) - sizes, sizes)
    local = np.arange(total) - first
    positions = np.repeat(complex_.loop_offsets[loops], sizes) + local
    keys, d = _reference_directions(complex_, positions)
    nxt = first + (local + 1) % np.maximum(np.repeat(sizes, sizes), 1)
    label = complex_.chart_label[complex_.loop_chart[loops]]
    normal = AXES[label // 2] * np.where(label % 2 == 0, 1.0, -1.0)[:, None]
    turn = np.rint(np.einsum("kj,kj->k", np.cross(d, d[nxt]),
                             np.repeat(normal, sizes, axis=0))).astype(np.int64)
    parallel = np.einsum("kj,kj->k", d, d[nxt])
    return keys, keys[nxt], turn, parallel, np.repeat(np.arange(len(loops)), sizes)


def _reference_directions(complex_, positions):
    """Sign keys (k,) int64 and unit directions (k, 3) of the loop references at ``positions``."""
    loop_of = np.searchsorted(complex_.loop_offsets, positions, side="right") - 1
    chart = complex_.loop_chart[loop_of]
    refs = complex_.loop_sides[positions]
    sides = np.where(refs >= 0, refs, ~refs)
    column = np.where(complex_.side_chart[sides, 0] == chart, 0, 1)
    slit = complex_.side_chart[sides, 0] == complex_.side_chart[sides, 1]
    key_column = np.where(slit, 0, column)
    walk = np.where(refs >= 0, 1.0, -1.0)
    directions = (AXES[complex_.side_axis[sides, column]]
                  * (complex_.side_sign[sides, column] * walk)[:, None])
    return sides * 2 + key_column, directions


def loop_turning(complex_):
    """(l,) int64 turning number of every loop with the current side directions (99 = reversal)."""
    n_loops = len(complex_.loop_chart)
    _, _, turn, parallel, loop_of = _loop_pairs(complex_, np.arange(n_loops))
    totals = np.bincount(loop_of, weights=turn, minlength=n_loops).astype(np.int64)
    reversed_ = np.bincount(loop_of, weights=parallel < -0.5, minlength=n_loops) > 0
    return np.where(reversed_, 99, totals)


def make_loops_rectilinear(complex_, collapsible=None, feasible_collapsible=None):
    """Flip the cheapest set of measured side directions so every chart can be a polygon.

    Every loop must turn by +4 (outer) or -4 (hole), and the charts must close together: some
    positive side lengths (shared by the two charts of each side) close every loop along both
    of its axes. Without the second condition a labeling that winds like a helical staircase
    around a handle (short sides measured the wrong way on a noisy surface) has rectilinear
    charts that no lengths can close. Lengths are continuous here (closure is homogeneous, so a
    rational solution scales to integers); the side-length bound ``CLOSURE_BOUND`` linearises
    the product of a flip and a length.

    Parameters
    ----------
    complex_ : ChartComplex
    collapsible : (s,) bool sides allowed length zero in the closure check, or None.
    feasible_collapsible : (s,) bool, a superset of ``collapsible`` with which this program is
        known to have a solution, or None. Every neighbourhood holding no side of the
        difference then has a solution, so the search for a contradiction
        (:func:`_local_contradiction`) tries only the others, and before the first solve
        (a retry with fewer collapsible sides is then much quicker).

    Returns
    -------
    complex_ : ChartComplex with ``side_sign`` repaired (the input when nothing changes).
    flipped : (f, 2) int64 rows (side, column) whose direction was reversed.

    Raises
    ------
    LabelingError naming the charts when no choice of directions makes them rectilinear.
    """
    collapsible = (np.zeros(complex_.n_sides, dtype=bool) if collapsible is None
                   else np.asarray(collapsible, dtype=bool))
    if feasible_collapsible is not None:
        feasible_collapsible = np.asarray(feasible_collapsible, dtype=bool)
        if (collapsible & ~feasible_collapsible).any():
            raise InternalError("feasible_collapsible must hold every collapsible side")
    if loops_are_rectilinear(complex_) and charts_close(complex_, collapsible):
        return complex_, np.zeros((0, 2), dtype=np.int64)
    program = _direction_program(complex_, np.arange(complex_.n_charts), collapsible)
    searched = feasible_collapsible is not None
    if searched:
        _raise_on_contradiction(complex_, collapsible,
                                np.flatnonzero(feasible_collapsible & ~collapsible))
    result = _solve(program, ROOT_NODES)
    if result.status == LIMIT_REACHED:
        # not decided within ROOT_NODES: a neighbourhood that cannot close is a quick proof
        # that the whole program is infeasible; without one, the full search. A program with
        # a solution found already has none (each neighbourhood's program is a relaxation)
        if not searched and result.x is None:
            _raise_on_contradiction(complex_, collapsible)
        result = _solve(program, NODE_LIMIT)
    if result.x is None:
        bad = np.flatnonzero(np.isin(loop_turning(complex_), [-4, 4], invert=True))
        charts = np.unique(complex_.loop_chart[bad])
        raise SideDirectionError(
            f"no side directions make every chart a closed rectilinear polygon ({len(charts)} "
            f"charts do not turn by four, e.g. charts {charts[:5].tolist()});"
            f"{_lone_side_note(complex_, collapsible)} HiGHS says '{result.message}'. The "
            f"labeling is not a polycube there: try {OTHER_PARTS} or another labeling",
            collapsible)
    used = program.used
    flip = np.rint(result.x[:len(used)]).astype(bool)
    flat = complex_.side_sign.reshape(-1).copy()
    flat[used[flip]] *= -1
    sign = flat.reshape(-1, 2)
    slit = complex_.side_chart[:, 0] == complex_.side_chart[:, 1]
    sign[slit, 1] = sign[slit, 0]
    flipped = np.stack(np.divmod(used[flip], 2), axis=1)
    return replace(complex_, side_sign=sign), flipped


def lone_sides(complex_, collapsible, charts=None):
    """Walks that no side directions close: a single side along one of their axes.

    A walk is the outer boundary of a chart (its loop without the slits and what they reach)
    or the rim of a hole (the references inside a slit, :meth:`ChartComplex.slit_walks`).
    Along each axis it runs, a closed rectilinear walk has sides in both directions, so a
    single side along an axis closes only with length zero, and an outer boundary with one
    side along an axis cannot turn by four at all. These are the usual reasons why a valid
    labeling has no side directions: a triangle chart, or a hole whose rim lacks the wall
    facing one way.

    Parameters
    ----------
    complex_ : ChartComplex; collapsible : (s,) bool sides allowed length zero;
    charts : (k,) int64 charts to look at, or None for all.

    Returns
    -------
    list of ``(chart, hole, axis, side)``: ints, ``hole`` a bool, ``axis`` 0..2 in the
    chart's part frame. A hole's single side is listed only when it may not collapse.
    """
    found = []
    for walk, hole in chart_walks(complex_):
        loop = np.searchsorted(complex_.loop_offsets, walk[0], side="right") - 1
        chart = int(complex_.loop_chart[loop])
        if charts is not None and chart not in charts:
            continue
        refs = complex_.loop_sides[walk]
        sides = np.where(refs >= 0, refs, ~refs)
        plain = complex_.side_chart[sides, 0] != complex_.side_chart[sides, 1]
        _, d = _reference_directions(complex_, walk)
        axis = np.argmax(np.abs(d), axis=1)
        for along in np.unique(axis[plain]).tolist():
            alone = np.flatnonzero(plain & (axis == along))
            item = (chart, hole, int(along), int(sides[alone[0]])) if len(alone) == 1 else None
            if item and not (hole and collapsible[item[3]]) and item not in found:
                found.append(item)  # (nested slits of one hole walk round it alike)
    return found


def chart_walks(complex_):
    """Every walk of :func:`lone_sides`: the rims of holes, then the outer boundaries.

    Returns a list of ``(walk, hole)``: (k,) int64 positions into ``loop_sides`` and a bool.
    """
    slits = [walk for walk in complex_.slit_walks() if len(walk)]
    inside = np.zeros(len(complex_.loop_sides), dtype=bool)
    for walk in slits:
        inside[walk] = True
    walks = [(walk, True) for walk in slits]
    for loop in range(len(complex_.loop_chart)):
        walk = np.arange(complex_.loop_offsets[loop], complex_.loop_offsets[loop + 1])
        walks.append((walk[~inside[walk]], False))
    return walks


def _lone_side_note(complex_, collapsible, charts=None):
    """A sentence naming the first walk of ``charts`` with a single side along an axis, or ''."""
    found = lone_sides(complex_, collapsible, charts)
    if not found:
        return ""
    chart, hole, axis, side = found[0]
    other = [c for c in complex_.side_chart[side].tolist() if c != chart]
    where = "the rim of a hole in chart" if hole else "chart"
    return (f" {where} {chart} has a single side along {'xyz'[axis]} (with chart "
            f"{other[0]}), which no side lengths close{' or turn by four' * (not hole)};")


def _solve(program, node_limit):
    """``solve_milp`` of a :class:`_DirectionProgram` within ``node_limit`` nodes."""
    return solve_milp("the side-direction repair", program.cost, program.integrality,
                      program.bounds, program.constraints, node_limit=node_limit)


def _feasibility(program):
    """``solve_feasibility`` of a :class:`_DirectionProgram` within ``NODE_LIMIT`` nodes: for
    callers that read only whether it is ``INFEASIBLE``."""
    return solve_feasibility("the side-direction repair", program.cost, program.integrality,
                             program.bounds, program.constraints)


def _raise_on_contradiction(complex_, collapsible, stricter=None):
    """Raise LabelingError naming a neighbourhood that cannot close (see _local_contradiction)."""
    contradiction = _local_contradiction(complex_, collapsible, stricter)
    if contradiction is not None:
        charts, message = contradiction
        raise SideDirectionError(
            "no side directions make every chart a closed rectilinear polygon: chart "
            f"{charts[0]} and its {len(charts) - 1} neighbours {charts[1:6].tolist()}... "
            f"cannot close with sides of positive length;"
            f"{_lone_side_note(complex_, collapsible, charts)} HiGHS says '{message}'. The "
            f"labeling is not a polycube there: try {OTHER_PARTS} or another labeling",
            collapsible)


def _local_contradiction(complex_, collapsible, stricter=None):
    """The first chart whose neighbourhood alone admits no side directions, or None.

    A neighbourhood is a chart and the charts it shares a side with; its program
    (:func:`_direction_program`) is a relaxation of the whole one, so an infeasible
    neighbourhood proves the whole program infeasible. Neighbourhoods are tried smallest
    first (ties by chart), each within ``NODE_LIMIT`` nodes; one that reaches the limit proves
    nothing and the next is tried. ``stricter``: (k,) int64 sides that lost the freedom to
    collapse in a program otherwise known to have a solution, or None; then only the
    neighbourhoods holding one of them are tried, those holding most first (they are the likely
    contradictions, found among the first few tried instead of among the last). A
    neighbourhood holding a chart whose own program has no solution is infeasible without a
    search of its own (:func:`_charts_infeasible_alone`).

    Returns
    -------
    ``(charts, message)``: (k,) int64 the chart then its neighbours, and HiGHS's message; or
    None when every neighbourhood has a solution.
    """
    rings = _rings(complex_)
    sizes = [len(ring) for ring in rings]
    if stricter is None:
        order = np.lexsort((np.arange(len(rings)), sizes))
    else:
        held = np.array([np.isin(complex_.side_chart[stricter], ring).any(axis=1).sum()
                         for ring in rings], dtype=np.int64)
        order = np.lexsort((np.arange(len(rings)), sizes, -held))
        order = order[held[order] > 0]
    slits = complex_.slit_walks()
    # a chart holding no side that lost its freedom has a solution on its own
    alone = _charts_infeasible_alone(
        complex_, collapsible, slits,
        np.arange(complex_.n_charts) if stricter is None else complex_.side_chart[stricter])
    for chart in order:
        ring = rings[chart]
        held = [alone[c] for c in ring.tolist() if c in alone]
        result = held[0] if held else _feasibility(
            _direction_program(complex_, np.sort(ring), collapsible, slits))
        if result.status == INFEASIBLE:
            return ring.astype(np.int64), str(result.message)
    return None


def _rings(complex_):
    """Per chart, (k,) int64 the chart then the charts it shares a side with."""
    rings = []
    for chart in range(complex_.n_charts):
        sides = np.flatnonzero((complex_.side_chart == chart).any(axis=1))
        neighbours = np.unique(complex_.side_chart[sides])
        rings.append(np.concatenate([[chart], neighbours[neighbours != chart]]))
    return rings


def contradicting_charts(complex_, collapsible):
    """(k,) int64 the charts whose neighbourhood alone admits no side directions.

    Each is a proof that the whole side-direction program has none (see
    :func:`_local_contradiction`); a labeling with none of them may still have no solution, but
    their number measures how far a labeling is from one that closes.
    """
    slits = complex_.slit_walks()
    alone = _charts_infeasible_alone(complex_, collapsible, slits,
                                     np.arange(complex_.n_charts))
    bad = [chart for chart, ring in enumerate(_rings(complex_))
           if np.isin(ring, list(alone)).any()
           or _feasibility(_direction_program(complex_, np.sort(ring), collapsible,
                                              slits)).status == INFEASIBLE]
    return np.asarray(bad, dtype=np.int64)


def _charts_infeasible_alone(complex_, collapsible, slits, charts):
    """``{chart: HiGHS result}`` of those of ``charts`` (int64 array, any shape) whose own program (their
    loops and slit walks only) has no solution.

    A chart's program is a relaxation of that of every neighbourhood holding the chart, so each
    of these proves its neighbourhoods infeasible. The programs of single charts are small and
    decided at once, where a neighbourhood's can take thousands of nodes to prove infeasible.
    """
    alone = {}
    with_loops = np.unique(complex_.loop_chart)
    for chart in np.intersect1d(np.asarray(charts, dtype=np.int64).reshape(-1),
                                with_loops).tolist():
        result = _feasibility(_direction_program(complex_, np.array([chart]), collapsible,
                                                 slits))
        if result.status == INFEASIBLE:
            alone[chart] = result
    return alone


@dataclass
class _DirectionProgram:
    """The mixed-integer program of :func:`make_loops_rectilinear` over some charts.

    used : (f,) int64 sign keys (``side * 2 + column``) of its flip variables, the first f.
    cost, integrality, bounds, constraints : as ``scipy.optimize.milp``.
    """

    used: np.ndarray
    cost: np.ndarray
    integrality: np.ndarray
    bounds: Bounds
    constraints: list


def _direction_program(complex_, charts, collapsible, slits=None):
    """The side-direction program of the loops and slit walks of ``charts`` only.

    Over every chart it is the program of :func:`make_loops_rectilinear`. Over a subset its
    rows are a subset of those rows on a subset of the variables, so it is a relaxation: when
    it is infeasible, so is the whole program.

    Parameters
    ----------
    complex_ : ChartComplex; charts : (c',) int64 sorted chart indices;
    collapsible : (s,) bool sides allowed length zero; slits : ``complex_.slit_walks()`` when
    already made, or None.

    Returns
    -------
    _DirectionProgram
    """
    loops = np.flatnonzero(np.isin(complex_.loop_chart, charts))
    keys, pair_b, turn, parallel, loop_of_pair = _loop_pairs(complex_, loops)
    turn = turn.astype(np.float64)
    used = np.unique(keys)
    nf = len(used)
    a = np.searchsorted(used, keys)
    b = np.searchsorted(used, pair_b)
    npairs = len(a)
    n_loops = len(loops)
    sides, key_side = np.unique(used // 2, return_inverse=True)
    n_sides = len(sides)
    # variables: flips f (nf), pair products x (npairs), hole flags h (n_loops), side lengths
    # l (n_sides), flipped lengths y = f * l (nf), disagreements z (nd)
    length0 = nf + npairs + n_loops
    flipped0 = length0 + n_sides
    disagree0 = flipped0 + nf
    rows = _Rows()
    # x = fa XOR fb: four rows per pair, and collinear neighbours must keep going the same
    # way (flip both or neither): a fifth row fixing x
    x = nf + np.arange(npairs)
    collinear = np.abs(parallel) > 0.5
    first = np.concatenate([[0], np.cumsum(4 + collinear)])[:-1]
    for offset, (sign_a, sign_b, lower, upper) in enumerate(
            [(-1, 1, 0, np.inf), (1, -1, 0, np.inf), (-1, -1, -np.inf, 0), (1, 1, -np.inf, 2)]):
        rows.add_at(first + offset, np.stack([x, a, b], axis=1),
                    np.broadcast_to([1.0, sign_a, sign_b], (npairs, 3)), lower, upper)
    value = np.where(parallel[collinear] < 0, 1.0, 0.0)
    rows.add_at(first[collinear] + 4, x[collinear, None], np.ones((collinear.sum(), 1)),
                value, value)
    rows.close(int(npairs * 4 + collinear.sum()))
    # each loop turns by +4 (outer) or -4 (hole, h = 1)
    turning = np.flatnonzero(~collinear)
    rhs = 4.0 - np.bincount(loop_of_pair, weights=turn, minlength=n_loops)
    rows.add_entries(loop_of_pair[turning], nf + turning, -2.0 * turn[turning])
    rows.add_entries(np.arange(n_loops), nf + npairs + np.arange(n_loops),
                     np.full(n_loops, 8.0))
    rows.add_bounds(rhs, rhs)
    # every chart has exactly one outer loop
    loop_chart = complex_.loop_chart[loops]
    for chart in np.asarray(charts).tolist():
        mine = np.flatnonzero(loop_chart == chart)
        if len(mine):
            rows.add_row(nf + npairs + mine, np.ones(len(mine)), len(mine) - 1, len(mine) - 1)
    # y = f * l, linearised with the length bound
    big = CLOSURE_BOUND
    key = np.arange(nf)
    f, l, y = key, length0 + key_side, flipped0 + key
    for offset, (columns, values, lower, upper) in enumerate([
            ((y, f), (1.0, -big), -np.inf, 0.0), ((y, l), (1.0, -1.0), -np.inf, 0.0),
            ((y, l, f), (1.0, -1.0, -big), -big, np.inf)]):
        rows.add_at(3 * key + offset, np.stack(columns, axis=1),
                    np.broadcast_to(values, (nf, len(values))), lower, upper)
    rows.close(3 * nf)
    # closure of every walk along every axis it runs
    walk_row, walk_keys, coefficients, n_walk_rows = _closure_entries(complex_, loops, slits)
    k = np.searchsorted(used, walk_keys)
    rows.add_entries(np.concatenate([walk_row, walk_row]),
                     np.concatenate([length0 + key_side[k], flipped0 + k]),
                     np.concatenate([coefficients, -2.0 * coefficients]))
    rows.add_bounds(np.zeros(n_walk_rows), np.zeros(n_walk_rows))
    # disagreements z >= |f(side, 0) - f(side, 1)| of the two charts of a side within one part
    coupled = _coupled_sides(complex_, used)
    nd = len(coupled)
    z = disagree0 + np.arange(nd)
    for offset, (sign_0, sign_1) in enumerate([(-1.0, 1.0), (1.0, -1.0)]):
        rows.add_at(2 * np.arange(nd) + offset,
                    np.stack([z, coupled[:, 0], coupled[:, 1]], axis=1),
                    np.broadcast_to([1.0, sign_0, sign_1], (nd, 3)), 0.0, np.inf)
    rows.close(2 * nd)
    nvar = disagree0 + nd
    matrix = rows.matrix(nvar)
    extent = complex_.side_extent.reshape(-1)[used]
    disagree_cost = DISAGREEMENT_WEIGHT * 0.5 * (extent[coupled[:, 0]] + extent[coupled[:, 1]])
    cost = np.concatenate([0.5 * extent + 1e-9 * (1.0 + np.arange(nf)),
                           np.zeros(npairs + n_loops + n_sides + nf), disagree_cost])
    integrality = np.concatenate([np.ones(nf + npairs + n_loops), np.zeros(n_sides + nf),
                                  np.zeros(nd)])
    lower = np.concatenate([np.zeros(nf + npairs + n_loops),
                            np.where(collapsible[sides], 0.0, 1.0), np.zeros(nf + nd)])
    upper = np.concatenate([np.ones(nf + npairs + n_loops), np.full(n_sides + nf, big),
                            np.ones(nd)])
    return _DirectionProgram(used, cost, integrality, Bounds(lower, upper),
                             [LinearConstraint(matrix, rows.lower(), rows.upper())])


class _Rows:
    """The rows of a sparse linear program, built block by block.

    A block's rows follow the rows before it; within a block, rows are placed by index
    (:meth:`add_at`, then :meth:`close` with the block's row count) or appended one block of
    entries and bounds at a time (:meth:`add_entries` then :meth:`add_bounds`, or
    :meth:`add_row`).
    """

    def __init__(self):
        self._rows, self._cols, self._vals = [], [], []
        self._lower, self._upper = [], []
        self._n = 0
        self._pending = None

    def add_at(self, local_rows, columns, values, lower, upper):
        """Entries ``columns``/``values`` ((r, e) each) of rows ``local_rows`` ((r,)) of the
        open block, their bounds ``lower``/``upper`` (scalars or (r,))."""
        if self._pending is None:
            self._pending = []
        local_rows = np.asarray(local_rows, dtype=np.int64)
        width = np.shape(columns)[1] if len(local_rows) else 0
        self._rows.append(self._n + np.repeat(local_rows, width))
        self._cols.append(np.asarray(columns, dtype=np.int64).reshape(-1))
        self._vals.append(np.asarray(values, dtype=np.float64).reshape(-1))
        self._pending.append((local_rows, lower, upper))

    def close(self, count):
        """End the open block of ``count`` rows (every one placed by :meth:`add_at`)."""
        lower, upper = np.zeros(count), np.zeros(count)
        for local_rows, low, high in self._pending or ():
            lower[local_rows] = low
            upper[local_rows] = high
        self._lower.append(lower)
        self._upper.append(upper)
        self._n += count
        self._pending = None

    def add_entries(self, local_rows, columns, values):
        """Entries of the next block's rows ``local_rows`` (counted from the block's first)."""
        self._rows.append(self._n + np.asarray(local_rows, dtype=np.int64))
        self._cols.append(np.asarray(columns, dtype=np.int64))
        self._vals.append(np.asarray(values, dtype=np.float64))

    def add_bounds(self, lower, upper):
        """Close the block of :meth:`add_entries` with its rows' bounds ((r,) each)."""
        self._lower.append(np.asarray(lower, dtype=np.float64))
        self._upper.append(np.asarray(upper, dtype=np.float64))
        self._n += len(self._lower[-1])

    def add_row(self, columns, values, lower, upper):
        """One row of its own."""
        self.add_entries(np.zeros(len(columns), dtype=np.int64), columns, values)
        self.add_bounds([lower], [upper])

    def matrix(self, n_columns):
        """(rows, n_columns) CSR matrix in canonical form (indices sorted, duplicates
        summed), built directly: scipy's conversion from coordinates is a large share of the
        cost of the many small programs of a neighbourhood search."""
        rows, cols = np.concatenate(self._rows), np.concatenate(self._cols)
        values = np.concatenate(self._vals)
        order = np.lexsort((cols, rows))
        rows, cols, values = rows[order], cols[order], values[order]
        first = np.flatnonzero(np.concatenate([[True], (rows[1:] != rows[:-1])
                                               | (cols[1:] != cols[:-1])])) if len(rows) else \
            np.zeros(0, dtype=np.int64)
        data = np.add.reduceat(values, first) if len(first) else np.zeros(0)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[first], minlength=self._n))])
        return sp.csr_matrix((data, cols[first].astype(np.int32), indptr.astype(np.int32)),
                             shape=(self._n, n_columns))

    def lower(self):
        return list(np.concatenate(self._lower))

    def upper(self):
        return list(np.concatenate(self._upper))


def _coupled_sides(complex_, used):
    """(c, 2) int64 variable indices (into ``used``) of the two directions of every side whose
    charts lie in one part: a polycube gives them the same direction."""
    side, column = np.divmod(used, 2)
    same_part = (complex_.chart_part[complex_.side_chart[side, 0]]
                 == complex_.chart_part[complex_.side_chart[side, 1]])
    first = np.flatnonzero((column == 0) & same_part)
    second = np.searchsorted(used, used[first] + 1)
    ok = (second < len(used)) & (used[np.minimum(second, len(used) - 1)] == used[first] + 1)
    return np.stack([first[ok], second[ok]], axis=1).astype(np.int64).reshape(-1, 2)


def loops_are_rectilinear(complex_):
    """True when every chart has one loop turning by +4 and all its other loops by -4."""
    turning = loop_turning(complex_)
    if np.isin(turning, [-4, 4], invert=True).any():
        return False
    outer = np.bincount(complex_.loop_chart[turning == 4], minlength=complex_.n_charts)
    has_loop = np.bincount(complex_.loop_chart, minlength=complex_.n_charts) > 0
    return bool((outer[has_loop] == 1).all())


def _closure_entries(complex_, loops=None, slits=None):
    """Closure equations of loops and slit walks, one per axis they run along.

    ``loops`` : (k,) int64 loops whose equations (and those of their slit walks) are given, or
    None for every loop; ``slits``: ``complex_.slit_walks()`` when already made, or None.

    Returns ``(row, keys, coefficients, n_rows)``: per entry, (e,) int64 its equation, (e,)
    int64 sign key (``side * 2 + column``) and (e,) float64 signed unit direction; the lengths
    of an equation's sides times its coefficients add up to zero when the walk closes along
    that axis. Equations come walk by walk (the loops, then the slit walks), each walk's by
    axis; entries in walk order.
    """
    if loops is None:
        loops = np.arange(len(complex_.loop_chart))
    slits = [walk for walk in (complex_.slit_walks() if slits is None else slits) if len(walk)]
    slit_loop = np.searchsorted(complex_.loop_offsets, [walk[0] for walk in slits],
                                side="right") - 1
    inside = np.isin(slit_loop, loops) if len(slits) else np.zeros(0, dtype=bool)
    walks = ([np.arange(complex_.loop_offsets[loop], complex_.loop_offsets[loop + 1])
              for loop in loops]
             + [walk for walk, kept in zip(slits, inside) if kept])
    if not walks:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0), 0
    positions = np.concatenate(walks)
    walk_of = np.repeat(np.arange(len(walks)), [len(walk) for walk in walks])
    keys, d = _reference_directions(complex_, positions)
    axis = np.argmax(np.abs(d), axis=1)
    order = np.lexsort((np.arange(len(positions)), axis, walk_of))
    group = walk_of[order] * 3 + axis[order]
    starts = np.concatenate([[True], group[1:] != group[:-1]])
    row = np.cumsum(starts) - 1
    return (row, keys[order], d[order, axis[order]], int(starts.sum()))


def charts_close(complex_, collapsible=None):
    """True when side lengths >= 1 (>= 0 for ``collapsible`` sides) close every loop (an LP)."""
    from scipy.optimize import linprog

    rows, keys, vals, n_equations = _closure_entries(complex_)
    matrix = sp.csr_matrix((vals, (rows, keys // 2)), shape=(n_equations, complex_.n_sides))
    matrix.sum_duplicates()
    zero_ok = (np.zeros(complex_.n_sides, dtype=bool) if collapsible is None
               else np.asarray(collapsible, dtype=bool))
    result = linprog(np.zeros(complex_.n_sides), A_eq=matrix, b_eq=np.zeros(n_equations),
                     bounds=[(0.0 if c else 1.0, None) for c in zero_ok], method="highs")
    return result.status == 0

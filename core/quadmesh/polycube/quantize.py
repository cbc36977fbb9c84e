# SPDX-License-Identifier: LGPL-2.1-or-later
"""Integer chart polygons: every side of the chart complex gets an integer length.

Each chart is a rectilinear polygon in its label plane, walked with the chart on the left
(slits make every chart a disk, :mod:`core.quadmesh.polycube.chart_complex`). Its sides have integer
lengths ``l_s >= 1``, one unknown per side shared by the two charts (or the two banks of a
slit) it bounds, so the unit lattices of neighbouring charts meet with the same splits: the
layout is conforming with no T-junctions, inside a part and across part interfaces alike (parts
are assembled by construction).

A rectilinear polygon drawn from any side lengths can overlap itself. Every chart is therefore
split into rectangles first, combinatorially, by Tamassia's rectangular refinement of its turn
sequence: from every reflex corner the incoming side is extended to the first side ahead where
the turns add up to one left turn (its *front*), splitting that side in two. Each rectangle
closes when its opposite sides are equally long, and any lengths >= 1 that close every
rectangle draw every rectangle with positive area: no piece of a chart can fold over or
collapse, whatever the scale. Rectangles glued along a winding arm of a chart (a hook around a
notch) can still reach over each other, since only the inside of the chart is refined (Tamassia
refines the outer face too); :mod:`core.quadmesh.polycube.lattice` finds such overlaps.

Splitting every chart that way makes a layout several times larger than its features need
where a chart has many reflex corners (a plate around holes), so the base-mesh stage splits only
the charts whose integer polygon overlaps itself, and those only at the reflex corners next to
the overlap at first (``cuts`` of :func:`rectangular_refinement`, chosen by
:mod:`core.quadmesh.polycube.overlap_cuts`): the pieces then close as polygons of their own.

Cutting does not rule out every overlap, and cutting further makes the layout larger; two
boundary segments that cross can instead be kept apart by a linear row on the side
lengths (:func:`separation_rows`, the separations chosen by
:mod:`core.quadmesh.polycube.overlap_cuts`), since the corners of a chart are sums of its
signed side lengths along its walk.

Where short sides may collapse to length zero, the walk around every hole that a slit reaches
keeps a width of at least one unit along both axes (:func:`_open_hole_rows`), so a narrow hole
does not close and take a handle of the design with it.

The objective keeps the side lengths close to their measured lengths on the target times a
scale ``s`` (units per target length): ``min sum |l - s L|`` (a mixed-integer program solved by
HiGHS, ``scipy.optimize.milp``). Short sides land on one unit wherever the constraints allow,
which makes the layout coarse. The scale sets the number of unit squares, which is the number of
base-mesh quads; :func:`quantize_for_budget` searches it for a face budget.

Each side's cost ``t >= |l - g|`` is written with the convex hull of its integer points
(:func:`closeness_rows`): besides ``t >= l - g`` and ``t >= g - l``, the chord through
``(floor g, g - floor g)`` and ``(ceil g, ceil g - g)``. The chord holds at every integer
``l``, so the integer program and its optimum are unchanged, but its linear relaxation is much
tighter. Without slits and rectangles the closure rows are the node-arc rows of a network
(along each axis a side adds its length to one chart and takes it from the other), so with the
chord the relaxation is a convex-cost flow with integral vertex optima; slit and rectangle rows
break that structure in general, yet on the programs met in practice HiGHS's root LP is
integral and the program closes at once. Without the chord the relaxation lets the sides sit
at their real goals, and HiGHS spends seconds on cuts and heuristics at the root
(``benchmarks/BASEMESH_SPEED_RESULTS.md``). The optimum is then exact rather than within
``MILP_GAP``. Several lengths often reach the same closeness (it is flat when one side grows
and another shrinks on the same side of their goals), and another solver path would pick
another of them; a small cost per unit of side length (``LENGTH_COST``) prefers the shorter
ones, which gives the base meshes the closeness alone would give when they are unique.

A side is measured along its own axis only. Where a chart's boundary runs at a slant (a
tapering arm, a strut at an angle to the part's axes), what a side moves across its axis is
in no side, and the polygon closest to the side lengths can be far narrower or wider than the
chart: its quads are then stretched many times over on the target, and the fit of the cage
crosses itself there. With ``corner_cost``, the corners of such charts (:func:`drifting_charts`)
are also kept near their measured places, ``min sum |c - s C - t|`` over the corners ``c`` of a
chart (linear in the side lengths, :func:`corner_rows`), ``C`` measured and ``t`` a
free shift of the chart: the polygon then balances the slant over its sides. Those terms
break the network structure above, so the program takes more branching; the base-mesh stage
asks for them only for a layout that lost without them.

After Protais, Bourcier, Ledoux, Lévy, "Robust quantization for polycube maps" (CAD 2022);
Lyon, Campen, Kobbelt, "Quad layouts via constrained T-mesh quantization" (EG 2021); Tamassia,
"On embedding a graph in the grid with the minimum number of bends" (SIAM J. Comput. 1987).
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint

from core.errors import LabelingError, OTHER_PARTS
from core.quadmesh.polycube.milp_solve import NODE_LIMIT, solve_milp

MILP_GAP = 0.01
"""Relative optimality gap accepted from HiGHS (the objective is a soft closeness measure)."""
BUDGET_TOLERANCE = 0.25
"""The face budget is met when the face count is within this fraction of it."""
COLLAPSE_BELOW = 0.5
"""Sides measured shorter than this many units (at the budget's first scale) may get length
zero: slivers of the labeling collapse (:func:`collapsible_sides`)."""
EXTRA_COST = 1e-3
"""Objective weight of the lengths of inserted edges and split pieces (per unit)."""
LENGTH_COST = 1e-5
"""Objective weight of the side lengths (per unit): among lengths equally close to their goals
(module docstring), the shorter ones, whatever path the solver takes."""
CORNER_DRIFT = 1.0
"""Charts whose sides, at their measured lengths, put a corner more than this many units from
its measured place get the corner terms of :func:`quantize` (:func:`drifting_charts`)."""
CORNER_NODE_LIMIT = 200
"""Branch-and-bound nodes of a program with corner terms: their relaxation is seldom integral,
and the best layout found within a few hundred nodes is as good a balance of the slant."""
SCALE_ROUNDS = 10
"""Most scales tried by :func:`quantize_for_budget`."""
SCALE_PRECISION = 0.02
"""Relative width down to which :func:`quantize_for_budget` bisects the scale around the edge
of the face budget's band (about twice that in faces, less than one step of the layout's
staircase on cages of a few hundred faces)."""


@dataclass(frozen=True)
class LoopTables:
    """The loop references of a chart complex as flat tables (``complex_.loop_sides`` order).

    ref_chart, ref_side : (j,) int64 chart and side of every reference.
    ref_axis : (j,) int64 0 when the side runs along the chart's ``u`` axis (``b``), 1 along ``v``.
    ref_sign : (j,) int64 +1 when walking the reference increases that coordinate.
    ref_next : (j,) int64 the next reference along the same loop.
    chart_turn_sign : (c,) int64 +1 where ``(u, v)`` is counter-clockwise seen from outside
        (label +a), -1 where it is mirrored (label -a).
    ref_measured : (j, 2) float64 measured ``(u, v)`` of every reference's start corner: the
        target corner projected on the chart's in-plane axes of its part frame.
    """

    ref_chart: np.ndarray
    ref_side: np.ndarray
    ref_axis: np.ndarray
    ref_sign: np.ndarray
    ref_next: np.ndarray
    chart_turn_sign: np.ndarray
    ref_measured: np.ndarray


@dataclass(frozen=True)
class Refinement:
    """Rectangles of every chart and the equalities that close them.

    n_vars : int, unknowns: the side lengths (``0 .. n_sides-1``), then the pieces of split
        edges and the lengths of the inserted edges.
    equalities : (r, n_vars) CSR float64, rows that must be zero (splits and rectangle closure).
    extents : (q, n_vars) CSR float64, rows that must be >= 1: each rectangle's width and height.
    piece : (n_vars,) bool, unknowns that are pieces of a split edge (they may be zero: the
        inserted edge then meets a corner of the edge it splits).
    rectangles : int, rectangles of all charts.
    rectangle_chart : (rectangles,) int64 chart of each rectangle (its rows in ``extents`` are
        ``2 r`` for the width and ``2 r + 1`` for the height).
    """

    n_vars: int
    equalities: sp.csr_matrix
    extents: sp.csr_matrix
    piece: np.ndarray
    rectangles: int
    rectangle_chart: np.ndarray


@dataclass(frozen=True)
class IntegerPolycube:
    """Result of one quantization.

    side_length : (s,) int64 length of every side in units (>= 1).
    corner_uv : (j, 2) int64 integer ``(u, v)`` of every reference's start corner in its chart
        (the chart's first reference starts at ``(0, 0)``).
    scale : float, units per target length used in the objective.
    faces : int, unit squares of all chart polygons (= base-mesh quads).
    chart_faces : (c,) int64 unit squares of each chart.
    status : str, HiGHS status message.
    """

    side_length: np.ndarray
    corner_uv: np.ndarray
    scale: float
    faces: int
    chart_faces: np.ndarray
    status: str


def chart_plane_axes(label):
    """In-plane axes ``(b, d)`` of charts with the given labels (so ``e_b x e_d = e_a``)."""
    axis = np.asarray(label) // 2
    return (axis + 1) % 3, (axis + 2) % 3


def loop_tables(complex_, V, part_frames):
    """Flat reference tables of ``complex_`` (one loop per chart).

    V : (n, 3) float64 target vertices; part_frames : (P, 3, 3) float64 frames (rows x, y, z).

    Raises
    ------
    LabelingError when a chart has several boundary loops (a hole its slits did not reach) or
    a side runs along its chart's label axis.
    """
    counts = np.bincount(complex_.loop_chart, minlength=complex_.n_charts)
    if (counts != 1).any():
        bad = np.flatnonzero(counts != 1)
        raise LabelingError(f"{len(bad)} charts are not disks after cutting (e.g. charts "
                            f"{bad[:5].tolist()} with {counts[bad[:5]].tolist()} boundary loops)")
    refs = complex_.loop_sides
    n_loops = len(complex_.loop_chart)
    sizes = np.diff(complex_.loop_offsets)
    ref_loop = np.repeat(np.arange(n_loops), sizes)
    ref_chart = complex_.loop_chart[ref_loop]
    side = np.where(refs >= 0, refs, ~refs)
    walk = np.where(refs >= 0, 1, -1)
    column = np.where(complex_.side_chart[side, 0] == ref_chart, 0, 1)
    side_axis = complex_.side_axis[side, column]
    b_axis, d_axis = chart_plane_axes(complex_.chart_label[ref_chart])
    if ((side_axis != b_axis) & (side_axis != d_axis)).any():
        raise LabelingError("a side runs along the label axis of its own chart: the labeling is "
                            "not a polycube there")
    rows = np.arange(len(refs))
    rank = rows - complex_.loop_offsets[:-1][ref_loop]
    ref_next = np.where(rank == sizes[ref_loop] - 1, complex_.loop_offsets[:-1][ref_loop],
                        rows + 1)
    corner = np.where(refs >= 0, complex_.side_corners[side, 0], complex_.side_corners[side, 1])
    frame = np.asarray(part_frames)[complex_.chart_part[ref_chart]]
    point = V[complex_.corner_vertex[corner]]
    measured = np.stack([np.einsum("rj,rj->r", point, frame[rows, b_axis]),
                         np.einsum("rj,rj->r", point, frame[rows, d_axis])], axis=1)
    return LoopTables(ref_chart, side, np.where(side_axis == b_axis, 0, 1),
                      complex_.side_sign[side, column] * walk, ref_next,
                      np.where(complex_.chart_label % 2 == 0, 1, -1), measured)


def _turn(a, b, turn_sign):
    """Turn (+1 left, -1 right, 0 straight) from direction ``a`` to ``b`` = (axis, sign)."""
    if a[0] == b[0]:
        if a[1] != b[1]:
            raise LabelingError("a chart boundary reverses along one axis: not a polycube")
        return 0
    cross = a[1] * b[1] * (1 if a[0] == 0 else -1)
    return turn_sign * cross


def _front(face, turns, i, measured=True):
    """The side the extension of side ``i`` of a face runs into, from its reflex end.

    Candidates are the sides ``k`` ahead where the turns from ``i`` add up to one left turn
    (Tamassia's rule: the extension meets a side of that direction). Among them the first one
    the extension meets in the measured chart is chosen (so the refinement follows the target);
    without a measured hit, or with ``measured`` False, the first candidate. Returns
    ``(k, hit)``: the side and the measured hit point (2,).
    """
    n = len(face)
    (axis, sign), _, _ = face[i]
    origin = face[(i + 1) % n][2]
    other = 1 - axis
    best, best_t, total = None, np.inf, 0
    for step in range(n):
        total += turns[(i + step) % n]
        if total != 1:
            continue
        k = (i + step + 1) % n
        start, end = face[k][2], face[(k + 1) % n][2]
        line = 0.5 * (start[axis] + end[axis])
        t = (line - origin[axis]) * sign
        low, high = min(start[other], end[other]), max(start[other], end[other])
        if best is None:
            best, best_line = k, line
        if measured and t > 0 and low <= origin[other] <= high and t < best_t:
            best, best_t, best_line = k, t, line
    hit = np.array(origin, dtype=np.float64)
    hit[axis] = best_line
    start, end = face[best][2], face[(best + 1) % n][2]
    hit[other] = np.clip(origin[other], min(start[other], end[other]),
                         max(start[other], end[other]))
    return best, hit


REFINEMENTS = ("measured", "first", "mirrored")
"""Ways to split a chart into rectangles: fronts met first in the measured chart, Tamassia's
first candidate fronts, or measured fronts of the loop walked backwards (each reflex corner
then extends its other side)."""


def rectangular_refinement(complex_, tables, refine=(), cuts=None):
    """Closure rows of every chart; the charts in ``refine`` are split into rectangles first.

    Parameters
    ----------
    complex_ : ChartComplex; tables : LoopTables.
    refine : dict chart -> one of ``REFINEMENTS`` (or a collection of charts, all
        ``"measured"``): charts split into rectangles (Tamassia's rectangular refinement of
        their turns, fronts by :func:`_front`); every other chart only closes as a whole
        polygon.
    cuts : dict chart -> set of references, or None: for the charts of ``refine`` in it, only
        the reflex corners at the start of these references are extended (a partial
        refinement: the pieces are closed polygons, rectangles where no reflex corner of
        theirs is cut); the other charts of ``refine`` extend every reflex corner.

    Returns
    -------
    Refinement
    """
    refine = dict(refine) if isinstance(refine, dict) else dict.fromkeys(refine, "measured")
    cuts = {} if cuts is None else cuts
    n_vars = complex_.n_sides
    rows, cols, vals = [], [], []
    ext_rows, ext_cols = [], []
    pieces, rectangle_chart = [], []
    n_rows = 0
    rectangles = 0
    order = np.argsort(tables.ref_chart, kind="stable")
    starts = np.searchsorted(tables.ref_chart[order], np.arange(complex_.n_charts + 1))
    for chart in range(complex_.n_charts):
        first = order[starts[chart]]
        walk, r = [], first
        while True:
            walk.append(r)
            r = tables.ref_next[r]
            if r == first:
                break
        sign = int(tables.chart_turn_sign[chart])
        # a face edge: ((axis, direction), length unknown, measured start point)
        face = [((int(tables.ref_axis[r]), int(tables.ref_sign[r])), int(tables.ref_side[r]),
                 tables.ref_measured[r]) for r in walk]
        # the reference whose start corner each face edge starts at (None: a point inserted
        # by a split)
        start_ref = list(walk)
        mode = refine.get(chart)
        if mode == "mirrored":
            # the same polygon walked backwards (interior on the right); each edge then starts
            # where it ended
            face = [((axis, -direction), var, face[(j + 1) % len(face)][2])
                    for j, ((axis, direction), var, _) in enumerate(face)][::-1]
            start_ref = [walk[(j + 1) % len(walk)] for j in range(len(walk))][::-1]
            sign = -sign
        chosen = cuts.get(chart) if chart in refine else None
        faces = [(face, start_ref)]
        while faces:
            face, start_ref = faces.pop()
            n = len(face)
            turns = [_turn(face[j][0], face[(j + 1) % n][0], sign) for j in range(n)]
            reflex = ([] if chart not in refine else
                      [j for j, t in enumerate(turns)
                       if t < 0 and (chosen is None or start_ref[(j + 1) % n] in chosen)])
            if not reflex:
                # a rectangle, a piece of a partial refinement or a whole chart closes: the
                # signed lengths along each axis add up to zero
                row = {0: {}, 1: {}}
                for (axis, direction), var, _ in face:
                    row[axis][var] = row[axis].get(var, 0) + direction
                for axis_row in row.values():
                    entries = [(v, c) for v, c in axis_row.items() if c != 0]
                    for v, c in entries:
                        rows.append(n_rows)
                        cols.append(v)
                        vals.append(float(c))
                    n_rows += 1
                if chart in refine and min(turns) >= 0:
                    for axis in (0, 1):
                        forward = sorted({var for (a, d), var, _ in face if a == axis and d > 0})
                        ext_rows += [2 * rectangles + axis] * len(forward)
                        ext_cols += forward
                    rectangles += 1
                    rectangle_chart.append(chart)
                continue
            i = reflex[0]
            k, hit = _front(face, turns, i, measured=mode != "first")
            direction_i, _, _ = face[i]
            dir_k, var_k, start_k = face[k]
            origin = face[(i + 1) % n][2]
            a, b, dummy = n_vars, n_vars + 1, n_vars + 2
            pieces += [a, b]
            n_vars += 3
            rows += [n_rows] * 3
            cols += [a, b, var_k]
            vals += [1.0, 1.0, -1.0]
            n_rows += 1
            back = (direction_i[0], -direction_i[1])
            ahead = [face[(i + 1 + j) % n] for j in range((k - i - 1) % n)]
            behind = [face[(k + 1 + j) % n] for j in range((i - k) % n)]
            ahead_refs = [start_ref[(i + 1 + j) % n] for j in range((k - i - 1) % n)]
            behind_refs = [start_ref[(k + 1 + j) % n] for j in range((i - k) % n)]
            faces.append((ahead + [(dir_k, a, start_k), (back, dummy, hit)],
                          ahead_refs + [start_ref[k], None]))
            faces.append(([(direction_i, dummy, origin), (dir_k, b, hit)] + behind,
                          [None, None] + behind_refs))
    # the walk inside every slit closes, so both banks of the slit coincide
    for walk in complex_.slit_walks():
        for axis in (0, 1):
            along = walk[tables.ref_axis[walk] == axis]
            if len(along):
                rows += [n_rows] * len(along)
                cols += tables.ref_side[along].tolist()
                vals += tables.ref_sign[along].astype(float).tolist()
                n_rows += 1
    equalities = sp.csr_matrix((vals, (rows, cols)), shape=(n_rows, n_vars))
    equalities.sum_duplicates()
    extents = sp.csr_matrix((np.ones(len(ext_rows)), (ext_rows, ext_cols)),
                            shape=(2 * rectangles, n_vars))
    piece = np.zeros(n_vars, dtype=bool)
    piece[pieces] = True
    return Refinement(n_vars, equalities, extents, piece, rectangles,
                      np.asarray(rectangle_chart, dtype=np.int64))


def corner_coordinates(complex_, tables, side_length):
    """(j, 2) int64 ``(u, v)`` of every reference's start corner, walking each chart's loop."""
    step = np.zeros((len(tables.ref_side), 2), dtype=np.int64)
    step[np.arange(len(step)), tables.ref_axis] = tables.ref_sign * side_length[tables.ref_side]
    uv = np.zeros_like(step)
    order = np.argsort(tables.ref_chart, kind="stable")
    starts = np.searchsorted(tables.ref_chart[order], np.arange(complex_.n_charts + 1))
    for chart in range(complex_.n_charts):
        r = first = order[starts[chart]]
        position = np.zeros(2, dtype=np.int64)
        while True:
            uv[r] = position
            position = position + step[r]
            r = tables.ref_next[r]
            if r == first:
                break
    return uv


def chart_unit_squares(complex_, tables, corner_uv):
    """(c,) int64 unit squares of every chart polygon (absolute value of its signed area)."""
    u, v = corner_uv[:, 0].astype(np.float64), corner_uv[:, 1].astype(np.float64)
    nxt = tables.ref_next
    cross = u * v[nxt] - u[nxt] * v
    signed = np.bincount(tables.ref_chart, weights=0.5 * cross, minlength=complex_.n_charts)
    return np.rint(np.abs(signed)).astype(np.int64)


def measured_lengths(complex_):
    """(s,) float64 measured length of every side along its axis (mean of its two frames)."""
    return complex_.side_extent.mean(axis=1)


def closeness_rows(goal, n_vars):
    """Rows ``t_s >= |l_s - goal_s|`` over the variables ``[l (n_vars), t (s)]``, exact on integers.

    Three rows per side: ``t >= l - g``, ``t >= g - l`` and the chord of ``|l - g|`` between
    the integers around ``g``, ``t >= (g - f) + (1 - 2 (g - f)) (l - f)`` with ``f = floor g``.
    Together they describe the convex hull of ``{(l, t): l integer, t >= |l - g|}`` (module
    docstring): every integer ``l`` keeps its cost ``|l - g|``.

    Parameters
    ----------
    goal : (s,) float64 goal length of every side (units); the sides are ``l[:s]``.
    n_vars : int, length unknowns ``l`` (sides first, then the refinement's unknowns).

    Returns
    -------
    scipy.optimize.LinearConstraint with 3 s rows and ``n_vars + s`` columns, each row ``>=``.
    """
    n_sides = len(goal)
    lengths = sp.identity(n_vars, format="csr")[:n_sides]
    slack = sp.identity(n_sides, format="csr")
    floor = np.floor(goal)
    slope = 1.0 - 2.0 * (goal - floor)
    rows = sp.vstack([sp.hstack([-lengths, slack]), sp.hstack([lengths, slack]),
                      sp.hstack([sp.diags(-slope) @ lengths, slack])])
    return LinearConstraint(rows.tocsr(), np.concatenate([-goal, goal,
                                                          goal - floor - slope * floor]), np.inf)


def _open_hole_rows(complex_, tables, n_columns):
    """Rows that keep every hole open: the walk inside each slit spans at least one unit along
    both axes of its chart.

    A slit cuts an annular chart (a plate around a hole) into a disk; the references between
    its two traversals walk around the hole (:meth:`ChartComplex.slit_walks`). Where short sides
    may collapse to length zero, a narrow hole could close to a segment, which removes a handle
    of the design; ``sum l >= 1`` over the references of the walk that advance along an axis
    keeps the hole at least one unit wide that way.

    Returns
    -------
    scipy.optimize.LinearConstraint with two rows per slit, ``n_columns`` columns (the side
    lengths first), each row ``>= 1``.
    """
    rows, cols = [], []
    n_rows = 0
    for walk in complex_.slit_walks():
        for axis in (0, 1):
            ahead = walk[(tables.ref_axis[walk] == axis) & (tables.ref_sign[walk] > 0)]
            if len(ahead):
                rows += [n_rows] * len(ahead)
                cols += tables.ref_side[ahead].tolist()
                n_rows += 1
    matrix = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_rows, n_columns))
    return LinearConstraint(matrix, 1.0, np.inf)


def corner_rows(tables, refs, scale, n_vars, n_sides):
    """Rows that make ``e`` at least the distance of every corner in ``refs`` from its
    measured place (:func:`quantize`'s corner terms), sparse.

    Each reference ``r`` of ``refs`` (whole loops: every reference of a chart or none) gets
    its start corner's integer place ``p_r`` (two free unknowns): walking the side of ``r``
    leads to the next corner, ``p_next = p_r + sign_r l_r e_axis``, which fixes the places up
    to one shift per chart, so ``e_r >= |p_r - scale C_r|`` measures each corner's distance
    from its measured place ``C_r`` after the chart's best shift.

    Parameters
    ----------
    tables : LoopTables; refs : (k,) int64 references; scale : float, units per length.
    n_vars : int, length unknowns (the side lengths first); n_sides : int, closeness slacks
        after them. The unknowns are ``[l (n_vars), t (n_sides), p (2 k), e (2 k)]``.

    Returns
    -------
    list of scipy.optimize.LinearConstraint: ``2 k`` walk equalities, then ``4 k`` rows
    ``>= 0`` for the distances.
    """
    k = len(refs)
    slot = np.full(len(tables.ref_side), -1, dtype=np.int64)
    slot[refs] = np.arange(k)
    nxt = slot[tables.ref_next[refs]]
    place = n_vars + n_sides + 2 * np.arange(k)[:, None] + np.array([0, 1])  # (k, 2) columns
    error = place + 2 * k
    n_columns = n_vars + n_sides + 4 * k
    rows = np.repeat(np.arange(2 * k), 2)
    cols = np.stack([place[nxt].reshape(-1), place.reshape(-1)], axis=1).reshape(-1)
    vals = np.tile([1.0, -1.0], 2 * k)
    walk_rows = 2 * np.arange(k) + tables.ref_axis[refs]
    rows = np.concatenate([rows, walk_rows])
    cols = np.concatenate([cols, tables.ref_side[refs]])
    vals = np.concatenate([vals, -tables.ref_sign[refs].astype(np.float64)])
    walk = sp.csr_matrix((vals, (rows, cols)), shape=(2 * k, n_columns))
    measured = scale * tables.ref_measured[refs].reshape(-1)
    ones = np.ones(2 * k)
    index = np.arange(2 * k)
    above = sp.csr_matrix((np.concatenate([-ones, ones]),
                           (np.concatenate([index, index]),
                            np.concatenate([place.reshape(-1), error.reshape(-1)]))),
                          shape=(2 * k, n_columns))
    below = sp.csr_matrix((np.concatenate([ones, ones]),
                           (np.concatenate([index, index]),
                            np.concatenate([place.reshape(-1), error.reshape(-1)]))),
                          shape=(2 * k, n_columns))
    return [LinearConstraint(walk, 0.0, 0.0),
            LinearConstraint(sp.vstack([above, below]).tocsr(),
                             np.concatenate([-measured, measured]), np.inf)]


def drifting_charts(complex_, tables, scale):
    """(k,) int64 charts whose sides drift: their corners, walked from the first one along the
    sides at their measured lengths (``scale`` times, in units), land more than
    ``CORNER_DRIFT`` units from the measured corners, after the shift that best matches the
    two (the mean offset).

    A side is measured along its own axis only; where the target's boundary runs at a slant
    (a tapering arm, a strut at an angle to the part's axes), what it moves across that axis
    is in no side, and the integer polygon is narrower or wider there than the chart it
    stands for.
    """
    goal = scale * measured_lengths(complex_)
    step = np.zeros((len(tables.ref_side), 2))
    step[np.arange(len(step)), tables.ref_axis] = tables.ref_sign * goal[tables.ref_side]
    order = np.argsort(tables.ref_chart, kind="stable")
    charts = np.unique(tables.ref_chart)
    starts = np.searchsorted(tables.ref_chart[order], charts)
    walked = np.zeros_like(step)
    for first in order[starts]:
        r, position = first, np.zeros(2)
        while True:
            walked[r] = position
            position = position + step[r]
            r = int(tables.ref_next[r])
            if r == first:
                break
    off = walked - scale * tables.ref_measured
    n = complex_.n_charts
    mean = np.stack([np.bincount(tables.ref_chart, weights=off[:, a], minlength=n)
                     for a in (0, 1)], axis=1) / np.maximum(
        np.bincount(tables.ref_chart, minlength=n), 1)[:, None]
    worst = np.zeros(n)
    np.maximum.at(worst, tables.ref_chart, np.abs(off - mean[tables.ref_chart]).max(axis=1))
    return np.flatnonzero(worst > CORNER_DRIFT)


def separation_rows(tables, separations, n_columns):
    """Rows that keep the corner pairs of ``separations`` at least one unit apart.

    The start corner of a reference lies at the signed sum of the lengths walked from the
    chart's first corner, so the offset along ``axis`` from the corner of ``low`` to that of
    ``high`` is ``sum sign_r l_r`` over the references ``r`` from ``low`` up to ``high`` (walking
    the loop forwards) that run along ``axis``.

    Parameters
    ----------
    tables : LoopTables; separations : sequence of
        :class:`core.quadmesh.polycube.overlap_cuts.Separation` (both references of one chart).
    n_columns : int, columns of the program (the side lengths first).

    Returns
    -------
    scipy.optimize.LinearConstraint with one row per separation, each row ``>= 1``.
    """
    rows, cols, vals = [], [], []
    for row, separation in enumerate(separations):
        ref = separation.low
        while ref != separation.high:
            if tables.ref_axis[ref] == separation.axis:
                rows.append(row)
                cols.append(int(tables.ref_side[ref]))
                vals.append(float(tables.ref_sign[ref]))
            ref = int(tables.ref_next[ref])
    matrix = sp.csr_matrix((vals, (rows, cols)), shape=(len(separations), n_columns))
    matrix.sum_duplicates()
    return LinearConstraint(matrix, 1.0, np.inf)


def quantize(complex_, tables, refinement, scale, collapsible=None, least=None, separations=(),
             corner_cost=0.0):
    """Integer side lengths closest to ``scale`` times the measured ones, every rectangle closed.

    Parameters
    ----------
    complex_ : ChartComplex; tables : LoopTables; refinement : Refinement.
    scale : float > 0, units per target length.
    collapsible : (s,) bool sides that may have length zero (slivers collapse), or None.
    least : (s,) int64 least length of every side (units), or None; where it exceeds the
        bound of ``collapsible`` (zero or one unit) it replaces it.
    separations : sequence of Separation, corner pairs kept apart (:func:`separation_rows`).
    corner_cost : float >= 0, objective weight (per unit, per axis) of the distance of every
        corner of a drifting chart (:func:`drifting_charts`) from its measured place, up to a
        shift of the chart (:func:`corner_rows`); 0 leaves the corners out.

    Returns
    -------
    IntegerPolycube

    Raises
    ------
    LabelingError when no integer lengths close every rectangle.
    """
    n_sides, n = complex_.n_sides, refinement.n_vars
    # variables [lengths (n), t (n_sides), shift (2 c), e (2 j)]: t >= |l - goal| for the side
    # lengths, e >= |corner - scale * measured corner - shift of its chart| for the corners
    refs = np.zeros(0, dtype=np.int64)
    if corner_cost > 0:
        refs = np.flatnonzero(np.isin(tables.ref_chart, drifting_charts(complex_, tables, scale)))
    n_refs = len(refs)
    extra = 4 * n_refs
    side_rows = closeness_rows(scale * measured_lengths(complex_), n)
    constraints = [
        LinearConstraint(sp.hstack([side_rows.A, sp.csr_matrix((side_rows.A.shape[0], extra))]),
                         side_rows.lb, side_rows.ub),
        LinearConstraint(sp.hstack([refinement.equalities,
                                    sp.csr_matrix((refinement.equalities.shape[0],
                                                   n_sides + extra))]), 0.0, 0.0),
        LinearConstraint(sp.hstack([refinement.extents,
                                    sp.csr_matrix((refinement.extents.shape[0],
                                                   n_sides + extra))]), 1.0, np.inf),
    ]
    if collapsible is not None and np.any(collapsible) and complex_.slit_walks():
        constraints.append(_open_hole_rows(complex_, tables, n + n_sides + extra))
    if len(separations):
        constraints.append(separation_rows(tables, separations, n + n_sides + extra))
    if n_refs:
        constraints += corner_rows(tables, refs, scale, n, n_sides)
    # inserted edges and split pieces carry a small cost: no larger than the sides need
    cost = np.concatenate([np.full(n_sides, LENGTH_COST), np.full(n - n_sides, EXTRA_COST),
                           np.ones(n_sides), np.zeros(2 * n_refs),
                           np.full(2 * n_refs, corner_cost)])
    integrality = np.concatenate([np.ones(n), np.zeros(n_sides + extra)])
    side_lower = np.ones(n_sides) if collapsible is None else np.where(collapsible, 0.0, 1.0)
    if least is not None:
        side_lower = np.maximum(side_lower, least)
    lower = np.concatenate([side_lower, np.where(refinement.piece[n_sides:], 0.0, 1.0),
                            np.zeros(n_sides), np.full(2 * n_refs, -np.inf),
                            np.zeros(2 * n_refs)])
    result = solve_milp("the side-length quantization", cost, integrality, Bounds(lower, np.inf),
                        constraints, MILP_GAP, CORNER_NODE_LIMIT if extra else NODE_LIMIT)
    if result.x is None:
        raise LabelingError(
            f"no integer side lengths close every rectangle of this labeling's charts "
            f"({n_sides} sides, {refinement.rectangles} rectangles): HiGHS says "
            f"'{result.message}'; try {OTHER_PARTS} or another labeling")
    side_length = np.rint(result.x[:n_sides]).astype(np.int64)
    corner_uv = corner_coordinates(complex_, tables, side_length)
    chart_faces = chart_unit_squares(complex_, tables, corner_uv)
    return IntegerPolycube(side_length, corner_uv, float(scale), int(chart_faces.sum()),
                           chart_faces, str(result.message))


def minimum_faces(complex_, tables, refinement, collapsible=None):
    """A lower bound on the unit squares of every layout that :func:`quantize` can return.

    Any lengths that close every rectangle of ``refinement`` and draw every chart as a polygon
    that :func:`core.quadmesh.polycube.lattice.build_lattice` accepts (a disk with integer corners)
    obey two linear bounds on each chart's area ``A``, so a linear program over real lengths
    (with the quantization's own constraints) gives a bound on their sum:

    - Pick's theorem, ``A = I + B / 2 - 1 >= P / 2 - 1`` with ``P`` the perimeter (the sum of
      the chart's side lengths, slit banks counted twice), for charts with no collapsible side
      (a collapsed chart or neck is not a disk);
    - for a chart split into rectangles, ``A = sum w h >= sum (w + h - 1)`` since every
      rectangle has ``w, h >= 1``.

    Parameters
    ----------
    complex_ : ChartComplex; tables : LoopTables; refinement : Refinement.
    collapsible : (s,) bool sides that may have length zero, or None.

    Returns
    -------
    int, the bound rounded up (0 when the linear program is infeasible: :func:`quantize` then
    says so).
    """
    from scipy.optimize import linprog

    n, n_sides, n_charts = refinement.n_vars, complex_.n_sides, complex_.n_charts
    zero_ok = (np.zeros(n_sides, dtype=bool) if collapsible is None
               else np.asarray(collapsible, dtype=bool))
    perimeter = sp.csr_matrix((np.ones(len(tables.ref_side)), (tables.ref_chart, tables.ref_side)),
                              shape=(n_charts, n))
    disk = np.bincount(tables.ref_chart, weights=zero_ok[tables.ref_side].astype(np.float64),
                       minlength=n_charts) == 0
    rectangles = sp.csr_matrix(
        (np.ones(2 * refinement.rectangles), (np.repeat(refinement.rectangle_chart, 2),
                                              np.arange(2 * refinement.rectangles))),
        shape=(n_charts, 2 * refinement.rectangles)) @ refinement.extents
    refined = np.bincount(refinement.rectangle_chart, minlength=n_charts)
    # variables [lengths (n), areas (c)]; rows A x - area <= rhs
    area = -sp.identity(n_charts, format="csr")
    upper = sp.vstack([sp.hstack([0.5 * perimeter[disk], area[disk]]),
                       sp.hstack([rectangles[refined > 0], area[refined > 0]]),
                       sp.hstack([-refinement.extents,
                                  sp.csr_matrix((refinement.extents.shape[0], n_charts))])])
    rhs = np.concatenate([np.ones(int(disk.sum())), refined[refined > 0].astype(np.float64),
                          -np.ones(refinement.extents.shape[0])])
    lower = np.concatenate([np.where(zero_ok, 0.0, 1.0),
                            np.where(refinement.piece[n_sides:], 0.0, 1.0), np.zeros(n_charts)])
    result = linprog(np.concatenate([np.zeros(n), np.ones(n_charts)]), A_ub=upper.tocsr(),
                     b_ub=rhs,
                     A_eq=sp.hstack([refinement.equalities,
                                     sp.csr_matrix((refinement.equalities.shape[0], n_charts))]),
                     b_eq=np.zeros(refinement.equalities.shape[0]),
                     bounds=np.stack([lower, np.full(len(lower), np.inf)], axis=1),
                     method="highs")
    if result.status != 0:
        return 0
    return int(np.ceil(result.fun - 1e-6))


def first_scale(complex_, target_faces):
    """Scale (units per target length) at which the charts' area is ``target_faces`` squares."""
    return float(np.sqrt(target_faces / max(float(complex_.chart_area.sum()), 1e-300)))


def collapsible_sides(complex_, target_faces):
    """(s,) bool sides shorter than ``COLLAPSE_BELOW`` units at :func:`first_scale`."""
    return measured_lengths(complex_) * first_scale(complex_, target_faces) < COLLAPSE_BELOW


def quantize_for_budget(complex_, tables, refinement, target_faces, collapsible=None,
                        give_up_faces=None, least=None, separations=(), corner_cost=0.0):
    """The quantization at the scale nearest the first one whose face count meets the budget.

    Starts from the scale that gives the target area in unit squares (:func:`first_scale`) and
    keeps that layout when its face count is within ``BUDGET_TOLERANCE`` of ``target_faces``.
    Otherwise the scale moves only as far as the band needs: the face count grows roughly with
    the square of the scale but in steps, so the scale is first extrapolated towards the budget
    until the band's nearer edge is crossed, then bisected (in log scale) between the scales on
    either side of that edge until they differ by at most ``SCALE_PRECISION`` and a layout in
    the band is found (or ``SCALE_ROUNDS`` are spent); the layout in the band at the scale
    nearest the first one is taken. The outcome then follows the first count: a first count
    just inside the band is kept, one just outside becomes the first step of the staircase
    inside it, not a layout near the budget (which would make two nearly equal targets, one
    design at two resolutions, give cages of very different sizes).

    When no scale gives a count in the band (a step of the staircase jumps over it), the layout
    closest to the budget is taken; when even a tiny scale gives too many faces, that is the
    minimum the constraints allow. With ``give_up_faces``, the search also stops once a scale of
    at most a quarter of the first one still gives more faces than that (the caller will not
    use so large a layout).

    Returns
    -------
    best : IntegerPolycube, the layout chosen as above.
    rounds : list of dicts with the scale and faces of every round (for the report).
    ``collapsible``, ``least``, ``separations`` and ``corner_cost`` are passed on to
    :func:`quantize`.
    """
    low_edge = (1.0 - BUDGET_TOLERANCE) * target_faces
    high_edge = (1.0 + BUDGET_TOLERANCE) * target_faces
    scale = first_scale(complex_, target_faces)
    rounds, closest, in_band = [], None, None
    below = None  # the first count is below the band (the scale grows), or above it
    outside, inside = None, None  # scales on the far and near side of the band's nearer edge
    for _ in range(SCALE_ROUNDS):
        result = quantize(complex_, tables, refinement, scale, collapsible, least, separations,
                          corner_cost)
        rounds.append({"scale": scale, "faces": result.faces})
        if closest is None or abs(result.faces - target_faces) < abs(closest.faces - target_faces):
            closest = result
        if low_edge <= result.faces <= high_edge and (
                in_band is None or _log_distance(scale, rounds[0]["scale"])
                < _log_distance(in_band.scale, rounds[0]["scale"])):
            in_band = result
        if len(rounds) == 1:
            if in_band is not None:
                break
            below = result.faces < low_edge
        crossed = result.faces >= low_edge if below else result.faces <= high_edge
        if crossed:
            inside = scale if inside is None else (min if below else max)(inside, scale)
        else:
            outside = scale if outside is None else (max if below else min)(outside, scale)
        if inside is not None and outside is not None:
            if in_band is not None and _log_distance(inside, outside) <= np.log1p(
                    SCALE_PRECISION):
                break
            scale = float(np.sqrt(inside * outside))
            continue
        if len(rounds) >= 3 and len({r["faces"] for r in rounds[-3:]}) == 1:
            break  # the constraints' minimum: smaller scales give the same layout
        if (give_up_faces is not None and result.faces > give_up_faces
                and scale <= 0.25 * rounds[0]["scale"]):
            break
        if len(rounds) > 1:
            scale *= 2.0 if below else 0.5
        else:
            scale *= float(np.sqrt(target_faces / max(result.faces, 1)))
    return (in_band if in_band is not None else closest), rounds


def _log_distance(a, b):
    """``|log(a / b)|`` of two positive scales."""
    return abs(float(np.log(a / b)))

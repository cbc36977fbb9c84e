# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reflex corners to cut, or crossing segments to keep apart, where an integer chart polygon
overlaps itself.

A chart polygon drawn from integer side lengths can overlap itself
(:mod:`core.quadmesh.polycube.lattice` finds cells covered twice or with the wrong orientation).
Splitting the whole chart into rectangles
(:func:`core.quadmesh.polycube.quantize.rectangular_refinement`) rules out most of that (not a
hooked arm of rectangles reaching over another), but every rectangle then needs a width and a height of at least one unit: a plate around several
holes, cut open by slits, has dozens of reflex corners, and its rectangles make the layout several
times larger than its features need.

A partial refinement extends only a few reflex corners: those next to the cells that overlap.
Each extension is a cut across the chart to the side ahead of the corner; the pieces on either
side close as polygons of their own, which ties the overlapping part of the boundary to the
far side of the chart (a hole's walk to the plate's rim), the relation the whole-chart closure
lacked. Where the chart still overlaps, the next quantization cuts at the corners next to the
new overlap; once every reflex corner is cut the pieces are Tamassia's rectangles, so the
escalation ends at the full refinement.

Cuts tie a chart into rectangles of at least one unit each, which can make a layout much larger
than the overlap needs. A lighter remedy separates the two boundary segments that cross
(:func:`crossing_separations`): of the ways two axis-parallel segments can lie apart (one
beyond an end of the other along either axis), the one the measured chart shows most clearly
becomes a linear row on the side lengths, a corner at least one unit beyond another along an
axis, as in the lazy validity constraints of Protais et al., "Robust quantization for polycube
maps" (CAD 2022).
"""
from dataclasses import dataclass

import numpy as np

from core.quadmesh.polycube.locate import winding_numbers
from core.quadmesh.polycube.quantize import _turn

NEAR_CELLS = 1.5
"""A reflex corner is next to an overlapping cell when it lies within this many units of the
cell's centre along both axes (the cell's own corners and the ring of cells around it)."""


def chart_walk(tables, chart):
    """(k,) int64 references of ``chart``'s loop in walking order."""
    first = int(np.flatnonzero(tables.ref_chart == chart)[0])
    walk, r = [], first
    while True:
        walk.append(r)
        r = int(tables.ref_next[r])
        if r == first:
            return np.asarray(walk, dtype=np.int64)


def reflex_references(tables, walk):
    """(k,) bool references of ``walk`` whose start corner is a reflex corner of the chart."""
    sign = int(tables.chart_turn_sign[tables.ref_chart[walk[0]]])
    direction = [(int(tables.ref_axis[r]), int(tables.ref_sign[r])) for r in walk]
    n = len(walk)
    return np.array([_turn(direction[j - 1], direction[j], sign) < 0 for j in range(n)])


def overlapping_cells(tables, corner_uv, walk, orientation):
    """(q, 2) int64 lower-left corners of the unit cells covered twice or backwards.

    corner_uv : (j, 2) int64 integer start corner of every reference; walk : (k,) int64 the
    chart's loop; orientation : +1 or -1, the loop's turning sense in ``(u, v)``.
    """
    start = corner_uv[walk]
    end = corner_uv[tables.ref_next[walk]]
    lo, hi = start.min(axis=0), start.max(axis=0)
    ii, jj = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
    cells = np.stack([ii.reshape(-1), jj.reshape(-1)], axis=1)
    winding = orientation * winding_numbers(cells + 0.5, start.astype(np.float64),
                                            end.astype(np.float64))
    return cells[(winding < 0) | (winding > 1)]


def corners_to_cut(tables, corner_uv, chart, orientation, already_cut):
    """References whose reflex start corners should be cut next in an overlapping chart.

    Parameters
    ----------
    tables : LoopTables; corner_uv : (j, 2) int64 the quantization's integer corners.
    chart : int, a chart whose polygon overlaps itself; orientation : +1 or -1 its loop's
        turning sense in ``(u, v)`` (:func:`core.quadmesh.polycube.lattice.chart_orientation`).
    already_cut : set of references cut already.

    Returns
    -------
    set of int: the uncut reflex corners next to the overlapping cells (module docstring), or
    the uncut ones nearest to them where none is next to them; empty when every reflex corner
    is cut or no cell overlaps.
    """
    walk = chart_walk(tables, chart)
    candidates = walk[reflex_references(tables, walk)]
    candidates = np.array([r for r in candidates.tolist() if r not in already_cut],
                          dtype=np.int64)
    cells = overlapping_cells(tables, corner_uv, walk, orientation)
    if not len(candidates) or not len(cells):
        return set()
    offset = np.abs(corner_uv[candidates][:, None, :] - (cells[None] + 0.5)).max(axis=2)
    nearest = offset.min(axis=1)
    near = nearest <= NEAR_CELLS
    if not near.any():
        near = nearest == nearest.min()
    return set(candidates[near].tolist())


@dataclass(frozen=True)
class Separation:
    """Two corners of one chart kept apart: the start corner of reference ``high`` lies at
    least one unit beyond that of reference ``low`` along ``axis`` (0 ``u``, 1 ``v``)."""

    low: int
    high: int
    axis: int


def crossing_separations(tables, corner_uv, chart):
    """Separations that would undo the crossings of ``chart``'s integer polygon, best first.

    Two references of the chart's loop (of different sides: the banks of a slit coincide by
    construction) cross when a ``u`` segment and a ``v`` segment meet inside both, or when two
    segments along one line overlap over more than a point. Each crossing yields the
    separation among the four that undo it (the crossing segment beyond either end of the
    other, along either axis); they are ordered by their margin in the measured chart
    (``tables.ref_measured``), largest first, so each crossing's clearest separation comes
    before its others.

    Parameters
    ----------
    tables : LoopTables; corner_uv : (j, 2) int64 the quantization's integer corners.
    chart : int.

    Returns
    -------
    list of Separation, four per crossing (empty when no two segments cross, e.g. a polygon
    that only touches itself).
    """
    walk = chart_walk(tables, chart)
    nxt = tables.ref_next[walk]
    axis, side = tables.ref_axis[walk], tables.ref_side[walk]
    start, end = corner_uv[walk], corner_uv[nxt]
    low_ref = np.where(tables.ref_sign[walk] > 0, walk, nxt)
    high_ref = np.where(tables.ref_sign[walk] > 0, nxt, walk)
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    i, j, parallel = _crossing_pairs(axis, side, start, lo, hi)
    # per crossing (i, j) in walk order: the v segment j left or right of the u segment i, or
    # i below or above j; for two segments along one line, one beside the other (across the
    # line, axis o), or beyond either of its ends (along it, axis a)
    a = axis[i]
    o = 1 - a
    low = np.where(parallel[:, None],
                   np.stack([walk[j], walk[i], high_ref[i], high_ref[j]], axis=1),
                   np.stack([walk[j], high_ref[i], walk[i], high_ref[j]], axis=1))
    high = np.where(parallel[:, None],
                    np.stack([walk[i], walk[j], low_ref[j], low_ref[i]], axis=1),
                    np.stack([low_ref[i], walk[j], low_ref[j], walk[i]], axis=1))
    along = np.where(parallel[:, None], np.stack([o, o, a, a], axis=1),
                     np.array([0, 0, 1, 1])[None, :])
    low, high, along = low.reshape(-1), high.reshape(-1), along.reshape(-1)
    measured = tables.ref_measured
    margin = measured[high, along] - measured[low, along]
    order = np.argsort(-margin, kind="stable")
    return [Separation(int(low[k]), int(high[k]), int(along[k])) for k in order.tolist()]


def _crossing_pairs(axis, side, start, lo, hi, block=256):
    """The crossing segment pairs of a chart's loop, in walk order (``i``, then ``j``).

    Parameters
    ----------
    axis, side : (k,) int the segments' axes and sides; start, lo, hi : (k, 2) int64 their
        start corners and the least and greatest coordinates of their ends.
    block : int, rows of the (k, k) pair table built at a time (memory).

    Returns
    -------
    (i, j, parallel): (p,) int64 the two segments of every crossing (of different sides) and
    (p,) bool whether they lie along one line (overlapping over more than a point, ``i < j``)
    rather than a ``u`` segment ``i`` and a ``v`` segment ``j`` meeting inside both.
    """
    k = len(axis)
    found_i, found_j, found_parallel = [], [], []
    for first in range(0, k, block):
        rows = np.arange(first, min(first + block, k))
        ai, aj = axis[rows][:, None], axis[None, :]
        apart = side[rows][:, None] != side[None, :]
        across = ((ai == 0) & (aj == 1)
                  & (lo[rows, 0][:, None] < start[None, :, 0])
                  & (start[None, :, 0] < hi[rows, 0][:, None])
                  & (lo[None, :, 1] < start[rows, 1][:, None])
                  & (start[rows, 1][:, None] < hi[None, :, 1]))
        a = axis[rows]
        o = 1 - a
        along_lo = np.maximum(lo[rows, a][:, None], lo[:, a].T)
        along_hi = np.minimum(hi[rows, a][:, None], hi[:, a].T)
        parallel = ((ai == aj) & (rows[:, None] < np.arange(k)[None, :])
                    & (start[rows, o][:, None] == start[:, o].T) & (along_lo < along_hi))
        ii, jj = np.nonzero(apart & (across | parallel))
        found_i.append(rows[ii])
        found_j.append(jj)
        found_parallel.append(parallel[ii, jj])
    return (np.concatenate(found_i).astype(np.int64), np.concatenate(found_j).astype(np.int64),
            np.concatenate(found_parallel))

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reflex corners to cut where an integer chart polygon overlaps itself.

A chart polygon drawn from integer side lengths can overlap itself
(:mod:`core.quadmesh.polycube.lattice` finds cells covered twice or with the wrong orientation).
Splitting the whole chart into rectangles
(:func:`core.quadmesh.polycube.quantize.rectangular_refinement`) rules that out for every length,
but every rectangle then needs a width and a height of at least one unit: a plate around several
holes, cut open by slits, has dozens of reflex corners, and its rectangles make the layout several
times larger than its features need.

A partial refinement extends only a few reflex corners: those next to the cells that overlap.
Each extension is a cut across the chart to the side ahead of the corner; the pieces on either
side close as polygons of their own, which ties the overlapping part of the boundary to the
far side of the chart (a hole's walk to the plate's rim), the relation the whole-chart closure
lacked. Where the chart still overlaps, the next quantization cuts at the corners next to the
new overlap; once every reflex corner is cut the pieces are Tamassia's rectangles, so the
escalation ends at the full refinement.
"""
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

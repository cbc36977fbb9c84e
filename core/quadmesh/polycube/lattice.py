# SPDX-License-Identifier: LGPL-2.1-or-later
"""Unit-lattice quads of the integer chart polygons.

Every chart of the integer polycube (:mod:`core.quadmesh.polycube.quantize`) is a rectilinear
polygon with integer corners; its unit squares are the base-mesh quads of that chart. A lattice
point on a side is named by the side and its distance from the side's start corner, so the two
charts of a side share its points (both see the same integer length): the quads are conforming with
no T-junctions, inside a part and across part interfaces alike. Lattice points inside a chart belong
to that chart only.
"""
from dataclasses import dataclass

import numpy as np

from core.errors import LabelingError, OTHER_PARTS
from core.quadmesh.polycube.locate import winding_numbers


class OverlappingChartsError(LabelingError):
    """Integer chart polygons that overlap or touch themselves; ``charts`` lists them."""

    def __init__(self, charts):
        self.charts = list(charts)
        super().__init__(
            f"{len(self.charts)} integer chart polygons overlap or touch themselves (e.g. charts "
            f"{self.charts[:5]}): the quantized layout is not valid there; try a larger "
            f"--target-faces or {OTHER_PARTS}")


@dataclass(frozen=True)
class Lattice:
    """The base-mesh quads and their lattice points, before the points are placed on the target.

    quads : (f, 4) int64 point indices, counter-clockwise seen from outside.
    quad_chart : (f,) int64 chart of each quad.
    n_corners : int, points ``0 .. n_corners-1`` are the corners of the chart complex.
    side_point_side, side_point_step : (p,) int64 side and distance from its start corner of
        points ``n_corners .. n_corners+p-1``.
    interior_chart : (i,) int64 chart of each interior point (the points after those).
    interior_uv : (i, 2) float64 their integer coordinates in the chart's plane.
    identified : (k, 2) int64 pairs of points that are one vertex: the two ends of a side of
        length zero, and the points of the two long sides of a chart of width zero (a sliver
        chart of the labeling that the quantization collapsed).
    """

    quads: np.ndarray
    quad_chart: np.ndarray
    n_corners: int
    side_point_side: np.ndarray
    side_point_step: np.ndarray
    interior_chart: np.ndarray
    interior_uv: np.ndarray
    identified: np.ndarray

    @property
    def n_points(self):
        return self.n_corners + len(self.side_point_side) + len(self.interior_chart)


def chart_orientation(complex_, tables, corner_uv):
    """(c,) int64 +1 where a chart's loops run counter-clockwise in its ``(u, v)`` plane, else
    -1."""
    u, v = corner_uv[:, 0].astype(np.float64), corner_uv[:, 1].astype(np.float64)
    nxt = tables.ref_next
    cross = u * v[nxt] - u[nxt] * v
    signed = np.bincount(tables.ref_chart, weights=cross, minlength=complex_.n_charts)
    return np.where(signed >= 0, 1, -1)


def build_lattice(complex_, tables, polycube):
    """Unit-square quads of every chart polygon with shared side and corner points.

    Parameters
    ----------
    complex_ : ChartComplex; tables : LoopTables; polycube : IntegerPolycube.

    Returns
    -------
    Lattice

    Raises
    ------
    OverlappingChartsError naming the charts whose integer polygon overlaps itself (cells
    covered twice or with the wrong orientation). Points of a chart that fall on one lattice
    point are identified (zero-length sides, collapsed charts); a chart that merely touches
    itself becomes a pinched vertex, which the base mesh's manifold check refuses.
    """
    corner_uv = polycube.corner_uv
    nxt = tables.ref_next
    orientation = chart_orientation(complex_, tables, corner_uv)
    refs = complex_.loop_sides
    lengths = polycube.side_length
    side_start = np.zeros(complex_.n_sides + 1, dtype=np.int64)
    side_start[1:] = np.cumsum(np.maximum(lengths - 1, 0))
    n_corners = complex_.n_corners
    corner_of_ref = np.where(refs >= 0, complex_.side_corners[tables.ref_side, 0],
                             complex_.side_corners[tables.ref_side, 1])
    ref_order = np.argsort(tables.ref_chart, kind="stable")
    chart_first = np.searchsorted(tables.ref_chart[ref_order], np.arange(complex_.n_charts + 1))

    quads, quad_chart, interior_chart, interior_uv, bad, identified = [], [], [], [], [], []
    next_interior = n_corners + int(side_start[-1])
    for chart in range(complex_.n_charts):
        mine = ref_order[chart_first[chart]:chart_first[chart + 1]]
        start, end = corner_uv[mine], corner_uv[nxt[mine]]
        points = {}
        for r, a, b in zip(mine.tolist(), start.tolist(), end.tolist()):
            side = tables.ref_side[r]
            length = int(lengths[side])
            if length == 0:
                identified.append((int(corner_of_ref[r]), int(corner_of_ref[nxt[r]])))
            step = (np.sign(b[0] - a[0]), np.sign(b[1] - a[1]))
            forward = refs[r] >= 0
            for k in range(length):
                key = (a[0] + k * step[0], a[1] + k * step[1])
                if k == 0:
                    name = int(corner_of_ref[r])
                else:
                    along = k if forward else length - k
                    name = n_corners + int(side_start[side]) + along - 1
                other = points.setdefault(key, name)
                if other != name:
                    identified.append((other, name))
        lo, hi = start.min(axis=0), start.max(axis=0)
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        cells = np.stack([ii.reshape(-1), jj.reshape(-1)], axis=1)
        winding = winding_numbers(cells + 0.5, start.astype(np.float64), end.astype(np.float64))
        winding *= orientation[chart]
        if (winding < 0).any() or (winding > 1).any():
            bad.append(chart)
            continue
        inside = cells[winding == 1]
        corners = np.stack([inside, inside + [1, 0], inside + [1, 1], inside + [0, 1]], axis=1)
        if orientation[chart] < 0:
            corners = corners[:, ::-1]
        ids = np.empty(corners.shape[:2], dtype=np.int64)
        for index, key in enumerate(map(tuple, corners.reshape(-1, 2).tolist())):
            name = points.get(key)
            if name is None:
                name = points[key] = next_interior
                next_interior += 1
                interior_chart.append(chart)
                interior_uv.append(key)
            ids.flat[index] = name
        quads.append(ids)
        quad_chart.append(np.full(len(ids), chart))
    if bad:
        raise OverlappingChartsError(bad)
    side_point_side = np.repeat(np.arange(complex_.n_sides), np.maximum(lengths - 1, 0))
    side_point_step = np.arange(len(side_point_side)) - side_start[side_point_side] + 1
    return Lattice(np.concatenate(quads), np.concatenate(quad_chart), n_corners,
                   side_point_side, side_point_step,
                   np.asarray(interior_chart, dtype=np.int64),
                   np.asarray(interior_uv, dtype=np.float64).reshape(-1, 2),
                   np.asarray(identified, dtype=np.int64).reshape(-1, 2))

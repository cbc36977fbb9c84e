# SPDX-License-Identifier: LGPL-2.1-or-later
"""Lattice points placed on the target surface.

Corners are the target's corner vertices. A point on a side lies on the side's vertex chain of
the target at the arc-length fraction ``step / length`` (computed once per side, so both charts
use the same point). Interior points come from a mean-value (Floater 2003) Tutte map of each
chart's region of the target onto its integer polygon: the region's boundary vertices are fixed
on the polygon by arc length along each side (the same fractions as the side points), every
interior vertex is the mean-value-weighted average of its neighbours (one sparse solve for all
charts), and a lattice point takes the target position of the same barycentric combination in
the mapped triangle that contains it. Such a map (positive weights) of a disk onto a convex
polygon cannot fold (Floater 1997); on non-convex chart polygons it can, near reflex corners,
and such a point then takes the triangle nearest to it. Nothing is taken from a
deformed polycube, so no fold of a polycube deformation can reach the base mesh.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from core.quadmesh.polycube.locate import locate_points

LOCATE_TOLERANCE = 1e-9
"""Barycentric slack for a lattice point on a mapped triangle's edge to count as inside."""


def arc_fractions(points):
    """(k,) float64 cumulative arc length of a polyline as a fraction of its length (0 .. 1)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    total = np.concatenate([[0.0], np.cumsum(seg)])
    return total / max(total[-1], 1e-300)


def point_on_chain(points, fractions, t):
    """(q, 3) positions at arc-length fractions ``t`` (q,) along a polyline."""
    index = np.clip(np.searchsorted(fractions, t, side="right") - 1, 0, len(points) - 2)
    span = np.maximum(fractions[index + 1] - fractions[index], 1e-300)
    w = ((t - fractions[index]) / span)[:, None]
    return (1.0 - w) * points[index] + w * points[index + 1]


def side_point_positions(V, complex_, lattice, side_length):
    """(p, 3) float64 target positions of the lattice points on sides."""
    out = np.zeros((len(lattice.side_point_side), 3))
    order = np.argsort(lattice.side_point_side, kind="stable")
    sides = lattice.side_point_side[order]
    starts = np.searchsorted(sides, np.arange(complex_.n_sides + 1))
    for side in np.unique(sides).tolist():
        rows = order[starts[side]:starts[side + 1]]
        chain = V[complex_.chain(side)]
        t = lattice.side_point_step[rows] / float(side_length[side])
        out[rows] = point_on_chain(chain, arc_fractions(chain), t)
    return out


def tutte_coordinates(V, F, complex_, tables, polycube):
    """Tutte map of every chart's region onto its integer polygon.

    Returns
    -------
    face_uv : (m, 3, 2) float64 the mapped position of each corner of each target face, in
        the ``(u, v)`` plane of the face's chart.
    """
    n = len(V)
    face_chart = complex_.face_chart
    refs = complex_.loop_sides
    nxt = tables.ref_next
    start_uv = polycube.corner_uv.astype(np.float64)
    end_uv = start_uv[nxt]
    keys, values = [], []
    for r in range(len(refs)):
        chain = complex_.chain(tables.ref_side[r])
        if refs[r] < 0:
            chain = chain[::-1]
        t = arc_fractions(V[chain])[:, None]
        keys.append(tables.ref_chart[r] * n + chain)
        values.append((1.0 - t) * start_uv[r] + t * end_uv[r])
    keys = np.concatenate(keys)
    values = np.concatenate(values)
    keys, first = np.unique(keys, return_index=True)
    values = values[first]

    # a vertex is interior to a chart when all its faces are in that chart
    corner_chart = np.repeat(face_chart, 3)
    vertex_min = np.full(n, np.iinfo(np.int64).max)
    vertex_max = np.full(n, -1)
    np.minimum.at(vertex_min, F.reshape(-1), corner_chart)
    np.maximum.at(vertex_max, F.reshape(-1), corner_chart)
    interior = vertex_min == vertex_max
    index_of = np.full(n, -1, dtype=np.int64)
    index_of[interior] = np.arange(int(interior.sum()))

    # mean-value weights (positive on any mesh): w_ij = sum over the corners at i of the
    # triangles on edge ij of tan(angle / 2) / |v_i - v_j|
    rows, cols, vals = [], [], []
    rhs = np.zeros((int(interior.sum()), 2))
    for k in range(3):
        i, j, l = F[:, k], F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        e1, e2 = V[j] - V[i], V[l] - V[i]
        n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        sine = np.linalg.norm(np.cross(e1, e2), axis=1)
        half_tan = sine / np.maximum(n1 * n2 + np.einsum("fk,fk->f", e1, e2), 1e-300)
        for q, length in ((j, n1), (l, n2)):
            own = interior[i]
            weight = half_tan[own] / np.maximum(length[own], 1e-300)
            p_, q_ = i[own], q[own]
            rows.append(index_of[p_])
            cols.append(index_of[p_])
            vals.append(weight)
            inner = interior[q_]
            rows.append(index_of[p_[inner]])
            cols.append(index_of[q_[inner]])
            vals.append(-weight[inner])
            pos = np.searchsorted(keys, face_chart[np.flatnonzero(own)[~inner]] * n + q_[~inner])
            np.add.at(rhs, index_of[p_[~inner]], weight[~inner, None] * values[pos])
    k = int(interior.sum())
    matrix = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(k, k))
    solved = splu(matrix).solve(rhs) if k else np.zeros((0, 2))
    face_uv = np.zeros((len(F), 3, 2))
    for column in range(3):
        vertex = F[:, column]
        inside = interior[vertex]
        face_uv[inside, column] = solved[index_of[vertex[inside]]]
        pos = np.searchsorted(keys, face_chart[~inside] * n + vertex[~inside])
        face_uv[~inside, column] = values[pos]
    return face_uv


def interior_point_positions(V, F, complex_, lattice, face_uv, orientation):
    """(i, 3) float64 target positions of the interior lattice points, and how many folded.

    Returns ``(positions, outside)``: ``outside`` counts points that lie in no correctly
    oriented mapped triangle of their chart (placed in the nearest one).
    """
    out = np.zeros((len(lattice.interior_chart), 3))
    outside = 0
    face_order = np.argsort(complex_.face_chart, kind="stable")
    face_start = np.searchsorted(complex_.face_chart[face_order], np.arange(complex_.n_charts + 1))
    point_order = np.argsort(lattice.interior_chart, kind="stable")
    point_start = np.searchsorted(lattice.interior_chart[point_order],
                                  np.arange(complex_.n_charts + 1))
    for chart in np.unique(lattice.interior_chart).tolist():
        faces = face_order[face_start[chart]:face_start[chart + 1]]
        points = point_order[point_start[chart]:point_start[chart + 1]]
        tri = face_uv[faces]
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        signed = (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) * orientation[chart]
        usable = np.abs(signed) > 0
        faces, tri, signed = faces[usable], tri[usable], signed[usable]
        index, bary, inside = locate_points(lattice.interior_uv[points], tri, signed < 0,
                                            LOCATE_TOLERANCE)
        outside += int((~inside | (signed[index] < 0)).sum())
        out[points] = np.einsum("qk,qkj->qj", bary, V[F[faces[index]]])
    return out, outside

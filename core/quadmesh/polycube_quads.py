# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh of one part from its polycube (paper Sect. 2.3, Fig. 4d).

Polycube grid method. In the part frame every chart of the deformed mesh
(:class:`core.polycube.deform.PolycubeDeformation`) is exactly planar and every boundary
between two charts lies on the line where their two planes meet. So with ``X_k`` the distinct
plane coordinates of the charts whose label axis is ``k`` (values closer than a tolerance
merged), a chart with label axis ``a`` is a rectilinear polygon whose edges lie on the lines
``u_b = x`` (``x`` in ``X_b``) and ``u_d = y`` (``y`` in ``X_d``) of its in-plane axes ``b``,
``d``. Cutting each chart along all of these lines gives rectangles; a rectangle belongs to the
chart when the chart boundary winds once around its centre. Every chart vertex is snapped to
the merged coordinate of each chart plane it lies on, so chains of nearly coincident planes
merge consistently. Because every chart uses the same global coordinates, two charts cut
their shared boundary at the same points: the quads conform (no T-junctions). A grid vertex
is named by three integer indices and the group of charts meeting there that are
neighbours on the target; sheets of a folded polycube that merely touch in the grid stay
apart. Optionally the gaps between neighbouring coordinates are split evenly (the same split
for every chart, so conformity is kept) until the mesh has about ``target_faces`` quads.

Each grid vertex is then located among the deformed triangles of one chart it belongs to
(2D, the chart's plane) and mapped to the target surface with the same barycentric
coordinates applied to the original triangle.

A folded polycube (flipped triangles, members collapsed to zero thickness, charts wound
backwards) can give a grid that is not a closed 2-manifold or has another genus than the
target; both raise a ``LabelingError`` naming the charts at fault.
"""
import time

import numpy as np

from core.errors import InvalidMeshError, LabelingError, ParameterError, StageNotAvailableError
from core.polymesh_checks import check_polymesh
from core.quadmesh.locate import locate_points, winding_numbers
from core.quadmesh.quad_ops import (chord_pieces, chord_refine, components, free_loop_merge,
                                     unmatched_half_edges)
from core.types import PolyMesh

MERGE_TOLERANCE = 1e-6
"""Plane coordinates closer than this times the polycube's bounding-box diagonal are merged."""
LOCATE_TOLERANCE = 1e-7
"""Barycentric slack for a grid vertex on a chart boundary to count as inside a triangle."""
MAX_CELLS = 2_000_000
"""Refuse grids with more candidate cells than this (a sign of a broken polycube)."""


def _by_chart(chart, n_charts):
    """Items grouped by chart: ``order[start[c]:start[c + 1]]`` are the items of chart ``c``.

    chart : (k,) int64 chart of each item. Returns ``(order (k,), start (n_charts + 1,))``.
    """
    order = np.argsort(chart, kind="stable")
    return order, np.searchsorted(chart[order], np.arange(n_charts + 1))


def _example(mask):
    return np.flatnonzero(mask)[:5].tolist()


def merge_coordinates(values, tolerance):
    """Distinct sorted coordinates, values closer than ``tolerance`` merged.

    Parameters
    ----------
    values : (k,) float64 plane coordinates.
    tolerance : float >= 0.

    Returns
    -------
    grid : (g,) float64 ascending representative (mean) of each group.
    index : (k,) int64 group of each input value.
    """
    order = np.argsort(values, kind="stable")
    s = values[order]
    new = np.concatenate([[True], np.diff(s) > tolerance])
    group_sorted = np.cumsum(new) - 1
    index = np.empty(len(values), dtype=np.int64)
    index[order] = group_sorted
    grid = np.bincount(group_sorted, weights=s) / np.bincount(group_sorted)
    return grid, index


def _chart_half_edges(F, face_chart):
    """Half-edges ``(face, corner)`` whose opposite half-edge lies in another chart.

    Returns (h,) int64 face, (h,) int64 corner ``k`` of edge ``F[f, k] -> F[f, k+1]`` and
    (h,) int64 face of the opposite half-edge.
    """
    m = len(F)
    a = F.reshape(-1)
    b = np.roll(F, -1, axis=1).reshape(-1)
    n = np.int64(F.max()) + 1
    key = a * n + b
    order = np.argsort(key, kind="stable")
    twin_pos = np.searchsorted(key[order], b * n + a)
    twin_pos = np.minimum(twin_pos, len(key) - 1)
    twin = order[twin_pos]
    found = key[twin] == b * n + a
    if not found.all():
        raise InvalidMeshError(f"target mesh is not closed: {int((~found).sum())} half-edges "
                               f"have no opposite, e.g. {_example(~found)}", reason="open",
                               count=int((~found).sum()), examples=_example(~found))
    face = np.repeat(np.arange(m), 3)
    boundary = face_chart[face] != face_chart[face[twin]]
    return face[boundary], np.tile(np.arange(3), m)[boundary], face[twin][boundary]


def _chart_grids(grids, lo_idx, hi_idx):
    """All candidate cells of all charts (vectorised).

    Returns (cell_chart, cell_i, cell_j) int64 arrays: cell ``(i, j)`` of chart ``c`` spans
    ``grids[b][i]..grids[b][i+1]`` and ``grids[d][j]..grids[d][j+1]``.
    """
    nb = np.maximum(hi_idx[:, 0] - lo_idx[:, 0], 0)
    nd = np.maximum(hi_idx[:, 1] - lo_idx[:, 1], 0)
    count = nb * nd
    total = int(count.sum())
    if total > MAX_CELLS:
        raise LabelingError(f"the polycube grid would have {total} cells (limit {MAX_CELLS}); "
                            f"the polycube has too many distinct plane coordinates "
                            f"({[len(g) for g in grids]} along x, y, z)")
    chart = np.repeat(np.arange(len(count)), count)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    local = np.arange(total) - start[chart]
    i = lo_idx[chart, 0] + local // np.maximum(nd[chart], 1)
    j = lo_idx[chart, 1] + local % np.maximum(nd[chart], 1)
    return chart, i, j


def base_mesh_from_polycube(target, polycube, face_label, face_part=None, part_frames=None,
                            target_faces=None, coarsen=True, merge_tolerance=MERGE_TOLERANCE,
                            locate_tolerance=LOCATE_TOLERANCE):
    """Closed quad base mesh on the target surface from a single-part polycube.

    Parameters
    ----------
    target : core.types.TriMesh, the closed target mesh (n vertices, m faces, outward).
    polycube : PolycubeDeformation of ``target`` (``local`` (n, 3) part-frame positions with
        exactly planar charts, ``face_chart``, ``chart_label``, ``chart_plane``, ``flipped``,
        ``degenerate``).
    face_label : (m,) int labels 0..5 (+X, -X, +Y, -Y, +Z, -Z of the part frame).
    face_part : (m,) int part of each face, or None (one part). Only one part is supported.
    part_frames : (P, 3, 3) float part frames (rows x, y, z), or None (identity); only the
        handedness of the frame is used (a left-handed frame reverses the face order).
    target_faces : int or None. If given and larger than the coarse mesh, every quad chord
        (strip of quads through opposite edges) is split into the same number of pieces,
        ``ceil(longest edge of the chord / h)``, with the largest spacing ``h`` that gives at
        least ``target_faces`` quads.
    coarsen : bool, remove free edge loops of the grid (closed edge lines through regular
        vertices only, inside charts), merging the quads on both sides (default True).
    merge_tolerance : float >= 0, plane coordinates closer than this times the polycube's
        bounding-box diagonal are one grid coordinate.
    locate_tolerance : float >= 0, barycentric slack for locating grid vertices.

    Returns
    -------
    mesh : core.types.PolyMesh, all quads, world coordinates, vertices on the target surface,
        closed, 2-manifold, outward (validated with ``check_polymesh``).
    info : dict (JSON-serialisable) with ``faces``, ``quads``, ``triangles``, ``other``,
        ``vertices``, ``edges``, ``extraordinary_vertices``, ``genus``, ``grid`` (coordinates
        per axis), ``grid_cells``, ``free_loops_removed``, ``coarse_faces`` (before
        refinement), ``spacing`` (chord spacing ``h`` or None), ``chart_faces`` (quads per
        chart), ``overlapping_cells`` (chart wound more than once: folded polycube),
        ``inverted_cells`` (chart wound negatively: kept with reversed orientation),
        ``located_in_flipped`` (vertices whose only containing triangle is flipped),
        ``located_outside`` (vertices in no chart triangle, snapped to the nearest),
        ``volume`` (enclosed by the quads), ``polycube_volume`` and ``seconds``.

    Raises
    ------
    ParameterError for malformed arguments; StageNotAvailableError for several parts;
    LabelingError when a chart is not a rectilinear polygon on the plane grid, the grid
    does not close into a 2-manifold or its genus differs from the target's (the message
    names the charts at fault: coincident, wound backwards or with non-manifold cells).
    """
    started = time.perf_counter()
    V = np.asarray(target.vertices, dtype=np.float64)
    F = np.asarray(target.faces, dtype=np.int64)
    m = len(F)
    U = np.asarray(polycube.local, dtype=np.float64)
    face_label = np.asarray(face_label, dtype=np.int64)
    if U.shape != V.shape:
        raise ParameterError(f"polycube.local must have the target's shape {V.shape}, "
                             f"got {U.shape}")
    if face_label.shape != (m,):
        raise ParameterError(f"face_label must be ({m},), got {face_label.shape}")
    face_chart = np.asarray(polycube.face_chart, dtype=np.int64)
    chart_label = np.asarray(polycube.chart_label, dtype=np.int64)
    if face_chart.shape != (m,) or not np.array_equal(chart_label[face_chart], face_label):
        raise ParameterError("polycube charts do not match face_label (was the polycube "
                             "computed from this labeling?)")
    if face_part is not None:
        parts = np.unique(np.asarray(face_part))
        if len(parts) > 1:
            raise StageNotAvailableError(
                f"base mesh of {len(parts)} parts: assembling part base meshes at their "
                f"interfaces is not implemented yet (single part only)")
    handed = 1.0
    if part_frames is not None:
        frames = np.asarray(part_frames, dtype=np.float64).reshape(-1, 3, 3)
        part = int(np.asarray(face_part).reshape(-1)[0]) if face_part is not None else 0
        handed = float(np.sign(np.linalg.det(frames[part])))
    if target_faces is not None and (isinstance(target_faces, bool)
                                     or not isinstance(target_faces, (int, np.integer))
                                     or target_faces < 6):
        raise ParameterError(f"target_faces must be None or an integer >= 6, got {target_faces!r}")

    n_charts = len(chart_label)
    chart_axis = chart_label // 2
    plane = np.asarray(polycube.chart_plane, dtype=np.float64)
    diag = float(np.linalg.norm(np.ptp(U, axis=0)))
    tol = merge_tolerance * diag
    snap_tol = max(tol, 1e-9 * diag)

    # global grid: merged plane coordinates along each axis
    grids, plane_index = [], np.zeros(n_charts, dtype=np.int64)
    for k in range(3):
        sel = np.flatnonzero(chart_axis == k)
        if len(sel) < 2:
            raise LabelingError(f"the polycube has {len(sel)} chart(s) facing axis {'xyz'[k]}; "
                                f"a closed polycube needs at least two")
        g, idx = merge_coordinates(plane[sel], tol)
        grids.append(g)
        plane_index[sel] = idx

    # every vertex lies on the plane of each chart around it: snap it to that grid coordinate
    grid_value = np.zeros(n_charts)
    for k in range(3):
        sel = np.flatnonzero(chart_axis == k)
        grid_value[sel] = grids[k][plane_index[sel]]
    corner_chart = np.repeat(face_chart, 3)
    corner_vertex = F.reshape(-1)
    corner_axis = chart_axis[corner_chart]
    off_plane = np.abs(U[corner_vertex, corner_axis] - plane[corner_chart]) > snap_tol
    bface, bcorner, nface = _chart_half_edges(F, face_chart)
    bchart, nchart = face_chart[bface], face_chart[nface]
    same_axis = chart_axis[bchart] == chart_axis[nchart]
    if off_plane.any() or same_axis.any():
        bad_charts = np.unique(np.concatenate([corner_chart[off_plane], bchart[same_axis]]))
        bad_faces = np.unique(np.concatenate([np.repeat(np.arange(m), 3)[off_plane],
                                              bface[same_axis]]))
        raise LabelingError(
            f"{len(bad_charts)} polycube charts are not rectilinear polygons on the plane grid "
            f"({int(off_plane.sum())} triangle corners off their chart plane, "
            f"{int(same_axis.sum())} boundary edges between charts of the same axis), "
            f"e.g. charts {bad_charts[:5].tolist()} at target faces {bad_faces[:5].tolist()}")
    adjacent = np.unique(np.minimum(bchart, nchart) * n_charts + np.maximum(bchart, nchart))
    snapped = U.copy()
    snapped[corner_vertex, corner_axis] = grid_value[corner_chart]

    # chart boundary edges in the in-plane coordinates of their chart
    b_ax = (chart_axis + 1) % 3
    d_ax = (chart_axis + 2) % 3
    va, vb = F[bface, bcorner], F[bface, (bcorner + 1) % 3]
    inplane = np.stack([b_ax[bchart], d_ax[bchart]], axis=1)
    pa = np.take_along_axis(snapped[va], inplane, axis=1)
    pb = np.take_along_axis(snapped[vb], inplane, axis=1)

    # extent of each chart in its in-plane axes, as grid indices (enclosing)
    lo_idx = np.zeros((n_charts, 2), dtype=np.int64)
    hi_idx = np.zeros((n_charts, 2), dtype=np.int64)
    for col in range(2):
        lo = np.full(n_charts, np.inf)
        hi = np.full(n_charts, -np.inf)
        np.minimum.at(lo, bchart, np.minimum(pa[:, col], pb[:, col]))
        np.maximum.at(hi, bchart, np.maximum(pa[:, col], pb[:, col]))
        for k in range(3):
            charts_k = np.flatnonzero((b_ax if col == 0 else d_ax) == k)
            charts_k = charts_k[np.isfinite(lo[charts_k])]
            g = grids[k]
            lo_idx[charts_k, col] = np.clip(np.searchsorted(g, lo[charts_k], side="right") - 1,
                                            0, len(g) - 1)
            hi_idx[charts_k, col] = np.clip(np.searchsorted(g, hi[charts_k], side="left"),
                                            0, len(g) - 1)
    cell_chart, cell_i, cell_j = _chart_grids(grids, lo_idx, hi_idx)

    # keep the cells the chart boundary winds around; the sign gives their orientation
    label_sign = np.where(chart_label % 2 == 0, 1, -1)
    wind = np.zeros(len(cell_chart), dtype=np.int64)
    b_order, b_start = _by_chart(bchart, n_charts)
    c_order, c_start = _by_chart(cell_chart, n_charts)
    for c in range(n_charts):
        cells = c_order[c_start[c]:c_start[c + 1]]
        if not len(cells):
            continue
        gb, gd = grids[b_ax[c]], grids[d_ax[c]]
        centre = np.stack([0.5 * (gb[cell_i[cells]] + gb[cell_i[cells] + 1]),
                           0.5 * (gd[cell_j[cells]] + gd[cell_j[cells] + 1])], axis=1)
        edges = b_order[b_start[c]:b_start[c + 1]]
        wind[cells] = label_sign[c] * winding_numbers(centre, pa[edges], pb[edges])
    keep = wind != 0
    overlapping = int((np.abs(wind) > 1).sum())
    inverted = int((wind < 0).sum())
    cell_chart, cell_i, cell_j = cell_chart[keep], cell_i[keep], cell_j[keep]
    cell_sign = np.sign(wind[keep]) * label_sign[cell_chart]
    grid_cells = len(cell_chart)

    # cells -> quads named by integer grid triples
    quads, cell_vertex_triples = _rectangle_quads(
        cell_chart, cell_i, cell_i + 1, cell_j, cell_j + 1, cell_sign * handed, chart_axis,
        plane_index, grids, adjacent)
    cells = (cell_chart, cell_i, cell_j, cell_sign, label_sign, plane_index)
    bad_half, _ = unmatched_half_edges(quads)
    if bad_half.any():
        bad_charts = np.unique(cell_chart[bad_half.reshape(-1, 4).any(axis=1)])
        raise LabelingError(
            f"the polycube grid does not close into a 2-manifold: {int(bad_half.sum())} cell "
            f"sides are not matched by exactly one opposite cell side (a folded or "
            f"self-overlapping polycube); {_fault_report(polycube, face_chart, cells, bad_charts)}")
    n_loops = 0
    if coarsen:
        try:
            merged, n_loops = free_loop_merge(quads, cell_chart * 2 + (cell_sign > 0))
        except InvalidMeshError as exc:
            raise LabelingError(f"the polycube grid does not close into a 2-manifold: {exc}") from exc
        k = int(merged.max()) + 1
        i0, j0 = np.full(k, np.iinfo(np.int64).max), np.full(k, np.iinfo(np.int64).max)
        i1, j1 = np.full(k, -1), np.full(k, -1)
        np.minimum.at(i0, merged, cell_i)
        np.minimum.at(j0, merged, cell_j)
        np.maximum.at(i1, merged, cell_i + 1)
        np.maximum.at(j1, merged, cell_j + 1)
        first = np.zeros(k, dtype=np.int64)
        first[merged[::-1]] = np.arange(len(merged))[::-1]
        if not np.array_equal(np.bincount(merged, minlength=k), (i1 - i0) * (j1 - j0)):
            raise LabelingError("removing free edge loops of the polycube grid left a face that "
                                "is not a rectangle")
        cell_chart, cell_sign = cell_chart[first], cell_sign[first]
        quads, cell_vertex_triples = _rectangle_quads(
            cell_chart, i0, i1, j0, j1, cell_sign * handed, chart_axis, plane_index, grids,
            adjacent)
    local_pos = np.stack([grids[k][cell_vertex_triples[:, k]] for k in range(3)], axis=1)
    coarse_faces = len(quads)
    quad_chart = cell_chart
    v_chart = np.zeros(len(local_pos), dtype=np.int64)
    v_chart[quads.reshape(-1)[::-1]] = np.repeat(quad_chart, 4)[::-1]

    # optional chord refinement towards target_faces
    spacing = None
    if target_faces is not None and coarse_faces < target_faces:
        try:
            spacing, pieces, edge = _spacing_for(quads, local_pos, target_faces)
            quads, local_pos, vertex_face, quad_face = chord_refine(quads, local_pos, pieces, edge)
        except InvalidMeshError as exc:
            raise LabelingError(f"the polycube grid does not close into a 2-manifold: {exc}") from exc
        v_chart = quad_chart[vertex_face]
        quad_chart = quad_chart[quad_face]

    # locate each grid vertex in its chart's deformed triangles, map to the target
    world, in_flipped, outside = _map_to_target(V, F, U, polycube, face_chart, v_chart, local_pos,
                                                b_ax, d_ax, n_charts, locate_tolerance)
    mesh = PolyMesh(world, quads.reshape(-1).astype(np.int64),
                    np.arange(0, 4 * len(quads) + 1, 4, dtype=np.int64))
    try:
        check_polymesh(mesh)
    except InvalidMeshError as exc:
        raise LabelingError(f"the polycube grid does not give a valid base mesh: {exc}") from exc
    poly_local = PolyMesh(local_pos * handed, mesh.face_vertices, mesh.face_offsets)
    info = mesh_statistics(mesh)
    target_chi = _euler_characteristic(F)
    if info["vertices"] - info["edges"] + info["faces"] != target_chi:
        raise LabelingError(
            f"the polycube grid has genus {info['genus']} but the target has genus "
            f"{(2 - target_chi) // 2}: the polycube lost or gained handles; "
            + _fault_report(polycube, face_chart, cells, np.zeros(0, dtype=np.int64)))
    info.update({
        "grid": [int(len(g)) for g in grids],
        "grid_cells": int(grid_cells),
        "free_loops_removed": int(n_loops),
        "coarse_faces": int(coarse_faces),
        "spacing": spacing,
        "chart_faces": np.bincount(quad_chart, minlength=n_charts).tolist(),
        "overlapping_cells": overlapping,
        "inverted_cells": inverted,
        "located_in_flipped": int(in_flipped.sum()),
        "located_outside": int(outside.sum()),
        "volume": polymesh_volume(mesh),
        "polycube_volume": polymesh_volume(poly_local),
        "seconds": round(time.perf_counter() - started, 4),
    })
    return mesh, info


def _euler_characteristic(F):
    """Euler characteristic (int) of a closed triangle mesh (m, 3) int64."""
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    n = np.int64(F.max()) + 1
    return len(np.unique(F)) - len(np.unique(edges[:, 0] * n + edges[:, 1])) + len(F)


def _chart_names(charts, polycube, face_chart):
    """'chart 4 (-X, x = 31.15, 162/3145 flipped triangles, e.g. target face 112)' list."""
    label = np.asarray(polycube.chart_label)
    flipped = np.asarray(polycube.flipped, dtype=bool)
    n_charts = len(label)
    total = np.bincount(face_chart, minlength=n_charts)
    n_flipped = np.bincount(face_chart[flipped], minlength=n_charts)
    example = np.full(n_charts, -1, dtype=np.int64)
    example[face_chart[::-1]] = np.arange(len(face_chart))[::-1]
    flip_example = np.full(n_charts, -1, dtype=np.int64)
    fl = np.flatnonzero(flipped)
    flip_example[face_chart[fl][::-1]] = fl[::-1]
    example = np.where(flip_example >= 0, flip_example, example)
    names = []
    for c in charts[:8]:
        sign, axis = "+-"[label[c] % 2], "XYZ"[label[c] // 2]
        names.append(f"chart {c} ({sign}{axis}, {axis.lower()} = "
                     f"{float(polycube.chart_plane[c]):.6g}, {n_flipped[c]}/{total[c]} flipped "
                     f"triangles, e.g. target face {example[c]})")
    more = f" and {len(charts) - 8} more" if len(charts) > 8 else ""
    return "; ".join(names) + more


def _fault_report(polycube, face_chart, cells, bad_charts):
    """Text naming the charts that break the grid: coincident, wound backwards, non-manifold.

    ``cells`` is ``(cell_chart, cell_i, cell_j, cell_sign, label_sign, plane_index)`` of the
    kept grid cells; ``bad_charts`` (k,) int64 charts where the grid is not manifold.
    """
    cell_chart, cell_i, cell_j, cell_sign, label_sign, plane_index = cells
    label = np.asarray(polycube.chart_label)
    parts = []
    # charts of one axis on the same grid plane covering the same cells: collapsed members
    span = np.int64(max(int(cell_i.max(initial=0)), int(cell_j.max(initial=0))) + 1)
    key = (((label[cell_chart] // 2) * (plane_index.max() + 1) + plane_index[cell_chart])
           * span + cell_i) * span + cell_j
    order = np.lexsort((cell_chart, key))
    dup = np.flatnonzero((key[order][1:] == key[order][:-1])
                         & (cell_chart[order][1:] != cell_chart[order][:-1]))
    if len(dup):
        pairs, count = np.unique(np.stack([cell_chart[order][dup], cell_chart[order][dup + 1]], 1),
                                 axis=0, return_counts=True)
        text = ", ".join(f"{a} and {b} ({n} cells)" for (a, b), n in zip(pairs[:5], count[:5]))
        coincident = np.unique(pairs)
        parts.append(f"charts on one plane cover the same grid cells (a member collapsed to "
                     f"zero thickness): {text}; {_chart_names(coincident, polycube, face_chart)}")
    inverted = np.unique(cell_chart[cell_sign != label_sign[cell_chart]])
    if len(inverted):
        parts.append(f"{len(inverted)} charts are wound backwards on the grid (folded "
                     f"polycube): {_chart_names(inverted, polycube, face_chart)}")
    if len(bad_charts):
        parts.append(f"non-manifold grid edges in {len(bad_charts)} charts: "
                     f"{_chart_names(bad_charts, polycube, face_chart)}")
    if not parts:
        return "no chart is individually at fault (check the polycube for self-intersections)"
    return " | ".join(parts)


def _rectangle_quads(chart, i0, i1, j0, j1, sign, chart_axis, plane_index, grids, adjacent):
    """Quads of grid rectangles, welded by integer grid position and chart adjacency.

    Rectangle ``r`` lies in the plane of ``chart[r]`` and spans grid indices ``i0..i1`` of the
    chart's first in-plane axis and ``j0..j1`` of the second; ``sign`` +1 orders its corners
    counter-clockwise about the positive label axis, -1 clockwise. Corners at the same grid
    position are one vertex when they belong to the same chart or to charts that are
    neighbours on the target (``adjacent``), joined transitively; so sheets of a folded
    polycube that only touch or overlap in the grid are not glued together.

    Parameters
    ----------
    adjacent : (p,) int64 sorted keys ``a * n_charts + b`` (a < b) of neighbouring charts.

    Returns quads (r, 4) int64 vertex ids and triples (v, 3) int64 grid indices per vertex.
    """
    n_charts = len(plane_index)
    axis = chart_axis[chart]
    b, d = (axis + 1) % 3, (axis + 2) % 3
    ci = np.stack([i0, i1, i1, i0], axis=1)
    cj = np.stack([j0, j0, j1, j1], axis=1)
    flip = sign < 0
    ci = np.where(flip[:, None], ci[:, ::-1], ci)
    cj = np.where(flip[:, None], cj[:, ::-1], cj)
    r = len(chart)
    triple = np.zeros((r, 4, 3), dtype=np.int64)
    rows, corner = np.arange(r)[:, None], np.arange(4)[None, :]
    triple[rows, corner, axis[:, None]] = plane_index[chart][:, None]
    triple[rows, corner, b[:, None]] = ci
    triple[rows, corner, d[:, None]] = cj
    sizes = np.array([len(g) for g in grids], dtype=np.int64)
    position = ((triple[..., 0] * sizes[1] + triple[..., 1]) * sizes[2]
                + triple[..., 2]).reshape(-1)
    # nodes: distinct (grid position, chart); union neighbouring charts at one position
    node_key = position * n_charts + np.repeat(chart, 4)
    node, first_corner, corner_node = np.unique(node_key, return_index=True, return_inverse=True)
    node_pos, node_chart = node // n_charts, node % n_charts
    group_start = np.flatnonzero(np.concatenate([[True], node_pos[1:] != node_pos[:-1]]))
    group_size = np.diff(np.concatenate([group_start, [len(node)]]))
    pa, pb = [], []
    for offset in range(1, int(group_size.max())):
        i = np.arange(len(node) - offset)
        same = node_pos[i] == node_pos[i + offset]
        i = i[same]
        lo = np.minimum(node_chart[i], node_chart[i + offset])
        hi = np.maximum(node_chart[i], node_chart[i + offset])
        key = lo * n_charts + hi
        pos = np.minimum(np.searchsorted(adjacent, key), max(len(adjacent) - 1, 0))
        joined = adjacent[pos] == key if len(adjacent) else np.zeros(len(key), dtype=bool)
        pa.append(i[joined])
        pb.append(i[joined] + offset)
    none = [np.zeros(0, dtype=np.int64)]
    component = components(len(node), np.concatenate(pa + none), np.concatenate(pb + none))
    # number vertices by their first corner (deterministic)
    first = np.full(component.max() + 1, len(position), dtype=np.int64)
    np.minimum.at(first, component, first_corner)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    vertex = rank[component[corner_node]]
    return vertex.reshape(r, 4), triple.reshape(-1, 3)[np.sort(first)]


def _spacing_for(quads, positions, target_faces):
    """Chord spacing ``h`` giving at least ``target_faces`` quads (largest such, bisection)."""
    edge_len = np.linalg.norm(positions[np.roll(quads, -1, axis=1)] - positions[quads], axis=2)
    hi = float(edge_len.max())
    lo = hi / (4.0 * np.sqrt(target_faces) + 1.0)
    pieces, edge = chord_pieces(quads, positions, lo)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        p, _ = chord_pieces(quads, positions, mid)
        he = edge.reshape(-1, 4)
        if int((p[he[:, 0]] * p[he[:, 1]]).sum()) >= target_faces:
            lo = mid
        else:
            hi = mid
    pieces, edge = chord_pieces(quads, positions, lo)
    return lo, pieces, edge


def _map_to_target(V, F, U, polycube, face_chart, v_chart, local_pos, b_ax, d_ax, n_charts,
                   tolerance):
    """World positions on the target of polycube points (located in their chart's triangles).

    Returns world (v, 3) float64, in_flipped (v,) bool (only a flipped triangle contains the
    point) and outside (v,) bool (no triangle of the chart contains it; nearest used).
    """
    usable = ~np.asarray(polycube.degenerate, dtype=bool)
    flipped = np.asarray(polycube.flipped, dtype=bool)
    nv = len(local_pos)
    world = np.zeros((nv, 3))
    in_flipped = np.zeros(nv, dtype=bool)
    outside = np.zeros(nv, dtype=bool)
    f_order, f_start = _by_chart(face_chart, n_charts)
    v_order, v_start = _by_chart(v_chart, n_charts)
    for c in range(n_charts):
        verts = v_order[v_start[c]:v_start[c + 1]]
        if not len(verts):
            continue
        faces_c = f_order[f_start[c]:f_start[c + 1]]
        faces_c = faces_c[usable[faces_c]]
        if not len(faces_c):
            raise LabelingError(f"polycube chart {c} has only degenerate triangles")
        cols = [b_ax[c], d_ax[c]]
        tri = U[F[faces_c]][:, :, cols]
        idx, bary, inside = locate_points(local_pos[verts][:, cols], tri, flipped[faces_c],
                                          tolerance)
        chosen = faces_c[idx]
        world[verts] = np.einsum("qk,qkj->qj", bary, V[F[chosen]])
        in_flipped[verts] = flipped[chosen] & inside
        outside[verts] = ~inside
    return world, in_flipped, outside


def polymesh_volume(mesh):
    """Signed volume (float, units cubed) enclosed by a closed polygon mesh (fan triangles)."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    fv, fo = mesh.face_vertices, mesh.face_offsets
    sizes = np.diff(fo)
    face = np.repeat(np.arange(len(sizes)), sizes)
    nxt = np.arange(len(fv)) + 1
    nxt[fo[1:] - 1] = fo[:-1]
    c = V.mean(axis=0)
    a = V[fv[fo[:-1]][face]] - c
    return float(np.sum(a * np.cross(V[fv] - c, V[fv[nxt]] - c))) / 6.0


def mesh_statistics(mesh):
    """Face kinds, valence and genus of a closed polygon mesh.

    Returns dict with ``faces``, ``quads``, ``triangles``, ``other``, ``vertices``,
    ``edges``, ``extraordinary_vertices`` (valence != 4) and ``genus`` (from the Euler
    characteristic, one connected component assumed).
    """
    fv, fo = mesh.face_vertices, mesh.face_offsets
    sizes = np.diff(fo)
    nxt = np.arange(len(fv)) + 1
    nxt[fo[1:] - 1] = fo[:-1]
    a, b = fv, fv[nxt]
    n = np.int64(len(mesh.vertices))
    und = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    valence = np.bincount(np.concatenate([und // n, und % n]), minlength=int(n))
    chi = int(n) - len(und) + len(sizes)
    return {
        "faces": int(len(sizes)), "quads": int((sizes == 4).sum()),
        "triangles": int((sizes == 3).sum()), "other": int((sizes > 4).sum()),
        "vertices": int(n), "edges": int(len(und)),
        "extraordinary_vertices": int((valence != 4).sum()),
        "genus": (2 - chi) // 2,
    }

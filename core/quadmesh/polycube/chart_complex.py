# SPDX-License-Identifier: LGPL-2.1-or-later
"""The polycube structure of a labelled target as a polygon complex of charts, sides and corners.

A valid polycube labeling splits the target surface into *charts* (connected faces of one part
and one label). Their boundaries split at *corners* (vertices with three or more
chart-separating edges, :mod:`core.segmentation.charts`) into *sides*: chains of target edges
between two corners, each between one pair of charts. In the polycube every side is a straight
edge along the axis perpendicular to both chart labels, and every chart is a rectilinear polygon
in its label plane. This module extracts that complex from the target alone (it never looks at a
deformed polycube): the sides with their vertex chains, direction and length measured on the
target, and every chart's boundary loops as cyclic sequences of sides.

Sides between two parts (interface sides) run, on each side, along the in-plane axis of that
side's chart in which the chain extends most; the remaining axis of that part is the axis of the
interface *cap*, the virtual chart that closes the part at the interface (all corners of one
interface loop share the cap's coordinate in that part).
"""
from dataclasses import dataclass

import numpy as np

from core.errors import LabelingError, OTHER_PARTS
from core.geometry import face_areas
from core.segmentation.charts import build_topology, extract_layout


class CornerlessLoopError(LabelingError):
    """A chart boundary loop passes no corner (:func:`cornerless_rims` lists them)."""


@dataclass(frozen=True)
class ChartComplex:
    """Charts, sides and corners of a labelled target (all indices are 0-based).

    face_chart : (m,) int64 chart of each target face.
    chart_label : (c,) int64 label 0..5 (+X, -X, +Y, -Y, +Z, -Z of the part frame).
    chart_part : (c,) int64 part of each chart.
    chart_area : (c,) float64 surface area of each chart (target units squared).
    corner_vertex : (q,) int64 target vertex of each corner.
    side_chart : (s, 2) int64 the chart on the left of the side (walking it from its start
        corner to its end corner, seen from outside) and the chart on the right.
    side_corners : (s, 2) int64 start and end corner of each side.
    side_axis : (s, 2) int64 axis 0..2 of the side in the part frame of the left and of the
        right chart (equal for sides inside one part).
    side_sign : (s, 2) int64 +1 when the side runs towards increasing coordinate along its
        axis (for each of the two charts' frames), else -1.
    side_extent : (s, 2) float64 measured length of the side along its axis (target units).
    side_offsets : (s + 1,) int64 CSR offsets into ``side_chain``.
    side_chain : (k,) int64 target vertices of every side from its start to its end corner.
    loop_chart : (l,) int64 chart of each boundary loop.
    loop_offsets : (l + 1,) int64 CSR offsets into ``loop_sides``.
    loop_sides : (j,) int64 signed side references along each loop, walked with the chart on
        the left: ``s`` for side ``s`` walked forward, ``~s`` (= -s - 1) walked backward.
    """

    face_chart: np.ndarray
    chart_label: np.ndarray
    chart_part: np.ndarray
    chart_area: np.ndarray
    corner_vertex: np.ndarray
    side_chart: np.ndarray
    side_corners: np.ndarray
    side_axis: np.ndarray
    side_sign: np.ndarray
    side_extent: np.ndarray
    side_offsets: np.ndarray
    side_chain: np.ndarray
    loop_chart: np.ndarray
    loop_offsets: np.ndarray
    loop_sides: np.ndarray

    @property
    def n_charts(self):
        return len(self.chart_label)

    @property
    def n_sides(self):
        return len(self.side_chart)

    @property
    def n_corners(self):
        return len(self.corner_vertex)

    def chain(self, side):
        """(k,) int64 target vertices of ``side`` from its start to its end corner."""
        return self.side_chain[self.side_offsets[side]:self.side_offsets[side + 1]]

    def slit_walks(self):
        """The references strictly between the two traversals of every slit side.

        Returns a list of (k,) int64 positions into ``loop_sides``, one per slit side: the walk
        around what the slit reaches (a former hole and whatever hangs off it). Such a walk must
        close by itself, so that the two banks of the slit coincide. (A slit whose banks lie on
        two loops, in a chart that is not a disk, has no walk.)

        The walks depend on the loops only (not on the side directions), and every program of
        a layout asks for them, so they are found once per complex (a new list each call).
        """
        cached = self.__dict__.get("_slit_walks")
        if cached is None:
            cached = self._find_slit_walks()
            object.__setattr__(self, "_slit_walks", cached)  # frozen: not a field, not copied
        return list(cached)

    def _find_slit_walks(self):
        """The walks of :meth:`slit_walks` (a list of (k,) int64, read-only)."""
        walks = []
        for loop in range(len(self.loop_chart)):
            a, b = self.loop_offsets[loop], self.loop_offsets[loop + 1]
            refs = self.loop_sides[a:b]
            sides = np.where(refs >= 0, refs, ~refs)
            slit = self.side_chart[sides, 0] == self.side_chart[sides, 1]
            for side in np.unique(sides[slit]).tolist():
                both = np.flatnonzero(sides == side)
                if len(both) == 2:
                    walk = a + np.arange(both[0] + 1, both[1], dtype=np.int64)
                    walk.flags.writeable = False
                    walks.append(walk)
        return walks

    def loop(self, index):
        """(j,) int64 signed side references of loop ``index`` (see ``loop_sides``)."""
        return self.loop_sides[self.loop_offsets[index]:self.loop_offsets[index + 1]]


def cornerless_rims(F, face_part, face_label):
    """The chart boundary loops that pass no corner (which no polycube face can have).

    Such a loop is the rim of a hole (or the foot of a boss) whose wall carries one label all
    round, so that nothing splits the rim into sides.

    Parameters
    ----------
    F : (m, 3) int64 faces of a closed 2-manifold; face_part, face_label : (m,) int64.

    Returns
    -------
    face_chart : (m,) int64 chart of each face (connected faces of one part and label).
    rims : list of ``(chart, rim, walls)``: the chart the loop bounds, (k,) int64 the loop's
        vertices and (j,) int64 the charts across it; one per loop.
    """
    F = np.asarray(F, dtype=np.int64)
    layout = extract_layout(build_topology(F, int(F.max()) + 1), np.asarray(face_part),
                            np.asarray(face_label))
    face_chart = layout.face_chart
    nxt, twin = _half_edge_tables(F)
    he_face = np.arange(3 * len(F)) // 3
    half = np.flatnonzero(face_chart[he_face] != face_chart[he_face[twin]])
    if not len(half):
        return face_chart, []
    succ = _chart_successors(half, face_chart, nxt, twin, np.zeros(3 * len(F), dtype=bool))
    he_from = F.reshape(-1)
    _, unvisited = _walk_loops(half, succ, layout.vertex_sep_degree[he_from[half]] >= 3)
    loops, _ = _walk_loops(half, succ, unvisited)
    rims = []
    for cycle in loops:
        run = half[cycle]
        walls = np.unique(face_chart[he_face[twin[run]]])
        rims.append((int(face_chart[he_face[run[0]]]), np.unique(he_from[run]), walls))
    return face_chart, rims


FACING = 0.1
"""Least mean cosine between the normals of the faces along a loop without corners and the
direction away from (or towards) the loop's axis for those faces to be said to face away from
(towards) it (:func:`_cornerless_loop_shape`)."""


def _cornerless_loop_shape(V, F, run, twin):
    """What a chart boundary loop without corners runs round, in words for an error message.

    The loop's axis is the normal of its least-squares plane through its centroid. Where the
    faces along the loop on both of its sides face away from the axis (mean cosine between
    their normals and the direction from the axis to them above :data:`FACING`), the loop
    runs round a member of the design (a neck of the surface); where they face towards it,
    round a hole through the design; otherwise it is the rim of a wall, boss or island. A
    member or hole whose faces two charts share round their loop has no walls of its own, and
    when it is a few triangles round, no labels can give it the four a polycube puts round it.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64 the target; run : (k,) int64 half-edges ``3 f + j``
        of the loop in order; twin : (3m,) int64 twin of every half-edge.

    Returns
    -------
    str, e.g. "it runs round a member 4 edges round and 2.3 units across".
    """
    points = V[F.reshape(-1)[run]]
    centre = points.mean(axis=0)
    axis = np.linalg.svd(points - centre)[2][-1]
    across = float(np.linalg.norm(points[:, None] - points[None], axis=2).max())
    facing = []
    for faces in (run // 3, twin[run] // 3):
        normal = np.cross(V[F[faces, 1]] - V[F[faces, 0]], V[F[faces, 2]] - V[F[faces, 0]])
        away = V[F[faces]].mean(axis=1) - centre
        away -= np.outer(away @ axis, axis)
        cosine = np.einsum("ij,ij->i", normal, away) / np.maximum(
            np.linalg.norm(normal, axis=1) * np.linalg.norm(away, axis=1), 1e-300)
        facing.append(float(cosine.mean()))
    size = f"{len(run)} edges round and {across:.3g} units across"
    if min(facing) > FACING:
        return (f"it runs round a member {size} whose faces the two charts share, so the "
                f"member has no walls of its own")
    if max(facing) < -FACING:
        return (f"it runs round a hole through the design {size} whose wall the two charts "
                f"share, so the hole has no walls of its own")
    return "it is the rim of a wall, boss or island that carries one label all round"


def _half_edge_tables(F):
    """Next half-edge in its face and twin half-edge of every half-edge ``3 f + k``.

    F : (m, 3) int64 faces of a closed 2-manifold. Returns ``(nxt, twin)``, both (3m,) int64.
    """
    m = len(F)
    a = F.reshape(-1)
    b = np.roll(F, -1, axis=1).reshape(-1)
    n = np.int64(F.max()) + 1
    key = a * n + b
    order = np.argsort(key, kind="stable")
    twin = order[np.searchsorted(key[order], b * n + a)]
    nxt = (np.arange(3 * m) // 3) * 3 + (np.arange(3 * m) % 3 + 1) % 3
    return nxt, twin


def _chart_successors(half, face_chart, nxt, twin, is_cut):
    """For each chart-boundary half-edge, the next one along its chart's boundary loop.

    Rotates around the end vertex through the faces of the same chart until the next
    half-edge leaving that vertex whose twin lies in another chart or that runs along a cut
    (works at pinched corners and along slits).
    """
    chart = face_chart[half // 3]
    succ = nxt[half]
    for _ in range(len(face_chart)):
        inside = (face_chart[twin[succ] // 3] == chart) & ~is_cut[succ]
        if not inside.any():
            break
        succ[inside] = nxt[twin[succ[inside]]]
    return succ


def _walk_loops(half, succ, starts):
    """Cycles of boundary half-edges (positions into ``half``), each started at a corner.

    Returns ``(loops, unvisited)``: list of (k,) int64 arrays and a bool mask of half-edges
    on loops that pass no corner.
    """
    position = np.full(int(half.max()) + 1 if len(half) else 0, -1, dtype=np.int64)
    position[half] = np.arange(len(half))
    succ_pos = position[succ]
    loop_of = np.full(len(half), -1, dtype=np.int64)
    loops = []
    for first in np.flatnonzero(starts):
        if loop_of[first] >= 0:
            continue
        cycle = [first]
        loop_of[first] = len(loops)
        cur = succ_pos[first]
        while cur != first:
            loop_of[cur] = len(loops)
            cycle.append(cur)
            cur = succ_pos[cur]
        loops.append(np.asarray(cycle, dtype=np.int64))
    return loops, loop_of < 0


def _slit_edges(V, F, face_chart, he_from, he_to, edges, loops, half, corner_degree):
    """Edges that cut every chart with several boundary loops into a disk.

    For each such chart the loops are joined one at a time, each to the nearest loop already
    joined, by a shortest path of target edges through the chart's interior (multi-source
    Dijkstra through interior vertices) that starts and ends away from corners. Each path is
    split at its middle vertex into two sides, so a slit can turn once (its two ends may meet
    sides of different axes).

    Returns ``(cut, middles)``: (e,) bool mask over the target's edges and (k,) int64 middle
    vertices (corners of the complex).
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    n = len(V)
    edge_key = edges[:, 0] * n + edges[:, 1]
    cut = np.zeros(len(edges), dtype=bool)
    middles = []
    he_face = half // 3
    loop_chart = np.array([face_chart[he_face[c[0]]] for c in loops], dtype=np.int64)
    counts = np.bincount(loop_chart, minlength=int(face_chart.max()) + 1)
    for chart in np.flatnonzero(counts > 1).tolist():
        mine = [i for i in range(len(loops)) if loop_chart[i] == chart]
        faces = np.flatnonzero(face_chart == chart)
        a = F[faces].reshape(-1)
        b = np.roll(F[faces], -1, axis=1).reshape(-1)
        vertex_loop = np.full(n, -1, dtype=np.int64)
        for i in mine:
            vertex_loop[he_from[half[loops[i]]]] = i
        endpoint = (vertex_loop >= 0) & (corner_degree < 3)
        blocked = np.zeros(n, dtype=bool)
        length = np.linalg.norm(V[a] - V[b], axis=1) + 1e-12
        lengths = [np.linalg.norm(V[he_to[half[loops[i]]]] - V[he_from[half[loops[i]]]],
                                  axis=1).sum() for i in mine]
        joined = {mine[int(np.argmax(lengths))]}
        while len(joined) < len(mine):
            # slits run through the chart's interior (no edge between two boundary vertices)
            # and never through an earlier slit
            keep = ~((vertex_loop[a] >= 0) & (vertex_loop[b] >= 0)) & ~blocked[a] & ~blocked[b]
            graph = sp.csr_matrix((length[keep], (a[keep], b[keep])), shape=(n, n))
            graph = graph.maximum(graph.T)
            sources = np.flatnonzero(endpoint & np.isin(vertex_loop, list(joined)))
            dist, pred, _ = dijkstra(graph, indices=sources, min_only=True,
                                     return_predecessors=True)
            targets = np.flatnonzero(endpoint & ~np.isin(vertex_loop, list(joined))
                                     & np.isfinite(dist))
            if len(targets) == 0:
                break
            v = int(targets[np.argmin(dist[targets])])
            joined.add(int(vertex_loop[v]))
            path = [v]
            while pred[v] >= 0:
                v = int(pred[v])
                path.append(v)
            for u, w in zip(path[:-1], path[1:]):
                cut[np.searchsorted(edge_key, min(u, w) * n + max(u, w))] = True
            middles.append(path[len(path) // 2])
            endpoint[path] = False
            blocked[path] = True
    return cut, np.asarray(middles, dtype=np.int64)


def build_chart_complex(V, F, face_part, face_label, face_frame, face_interface_axis=None):
    """Charts, sides, corners and chart boundary loops of a labelled closed triangle mesh.

    Charts with holes (several boundary loops) are cut into disks by slits: shortest interior
    paths joining their loops, each a side whose two banks belong to the same chart (walked
    once in each direction by the chart's single loop), so every chart is a simple polygon.

    Parameters
    ----------
    V : (n, 3) float64 target vertices.
    F : (m, 3) int64 target faces, outward (counter-clockwise seen from outside).
    face_part : (m,) int part of each face.
    face_label : (m,) int label 0..5 of each face in its frame.
    face_frame : (m, 3, 3) float64 frame of each face (rows x, y, z).
    face_interface_axis : (m, 3) float64 normal (x-axis) of the part interface next to each
        face, NaN rows where none (``FrameField.face_interface_axis``); None for one part.

    Returns
    -------
    ChartComplex

    Raises
    ------
    LabelingError when the labeling cannot be a polycube: a boundary between opposite labels
    (its side has no axis) or a chart boundary loop without corners.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    face_label = np.asarray(face_label, dtype=np.int64)
    topology = build_topology(F, len(V))
    layout = extract_layout(topology, face_part, face_label)
    face_chart = layout.face_chart
    nxt, twin = _half_edge_tables(F)
    m = len(F)
    he_face = np.repeat(np.arange(m), 3)
    he_from = F.reshape(-1)
    he_to = F[he_face, (np.arange(3 * m) % 3 + 1) % 3]
    he_edge = topology.face_edges.reshape(-1)
    separating = face_chart[he_face] != face_chart[he_face[twin]]
    no_cut = np.zeros(3 * m, dtype=bool)

    half = np.flatnonzero(separating)
    succ = _chart_successors(half, face_chart, nxt, twin, no_cut)
    loops, unvisited = _walk_loops(half, succ, layout.vertex_sep_degree[he_from[half]] >= 3)
    if unvisited.any():
        run = half[_walk_loops(half, succ, unvisited)[0][0]]
        chart = int(face_chart[he_face[run[0]]])
        across = int(face_chart[he_face[twin[run[0]]]])  # one chart: no corner, no change
        raise CornerlessLoopError(
            f"chart {chart} (label {_LABEL_NAMES[layout.chart_label[chart]]}, part "
            f"{int(layout.chart_part[chart])}) has a boundary loop without corners near "
            f"{np.round(V[he_from[run[0]]], 4).tolist()} (chart {across} across it): "
            f"{_cornerless_loop_shape(V, F, run, twin)}; a polycube face needs corners on each "
            f"boundary loop (try {OTHER_PARTS} or a different labeling)")
    cut_edge, middles = _slit_edges(V, F, face_chart, he_from, he_to, topology.edges, loops,
                                    half, layout.vertex_sep_degree)
    is_cut = cut_edge[he_edge]
    boundary_edge = np.zeros(len(topology.edges), dtype=bool)
    boundary_edge[layout.sep_edges] = True
    boundary_edge |= cut_edge
    degree = np.bincount(topology.edges[boundary_edge].reshape(-1), minlength=len(V))
    degree[middles] = 3
    corners = np.flatnonzero(degree >= 3)
    corner_of_vertex = np.full(len(V), -1, dtype=np.int64)
    corner_of_vertex[corners] = np.arange(len(corners))

    half = np.flatnonzero(separating | is_cut)
    succ = _chart_successors(half, face_chart, nxt, twin, is_cut)
    starts_at_corner = corner_of_vertex[he_from[half]] >= 0
    loops, _ = _walk_loops(half, succ, starts_at_corner)
    loop_charts = [int(face_chart[he_face[half[c[0]]]]) for c in loops]

    # a side is a run of boundary half-edges between two corners; its two traversals (one per
    # bank) share their edges, so the run's lowest edge index names the side
    side_of_key = {}
    side_half_lists, side_left, side_right, loop_side_lists = [], [], [], []
    for cycle in loops:
        cut_at = np.flatnonzero(starts_at_corner[cycle])
        refs = []
        for a, b in zip(cut_at, np.append(cut_at[1:], len(cycle))):
            run = half[cycle[a:b]]
            key = int(he_edge[run].min())
            chart = int(face_chart[he_face[run[0]]])
            side = side_of_key.get(key)
            if side is None:
                side = side_of_key[key] = len(side_half_lists)
                side_half_lists.append(run)
                side_left.append(chart)
                side_right.append(-1)
                refs.append(side)
            else:
                side_right[side] = chart
                refs.append(~side)
        loop_side_lists.append(refs)
    n_sides = len(side_half_lists)
    side_left = np.asarray(side_left, dtype=np.int64)
    side_right = np.asarray(side_right, dtype=np.int64)
    side_offsets = np.zeros(n_sides + 1, dtype=np.int64)
    side_offsets[1:] = np.cumsum([len(r) + 1 for r in side_half_lists])
    side_chain = np.concatenate([np.append(he_from[r], he_to[r[-1]]) for r in side_half_lists])
    side_corners = np.stack([corner_of_vertex[side_chain[side_offsets[:-1]]],
                             corner_of_vertex[side_chain[side_offsets[1:] - 1]]], axis=1)
    side_chart = np.stack([side_left, side_right], axis=1)

    chart_label = layout.chart_label
    if face_interface_axis is None:
        face_interface_axis = np.full((m, 3), np.nan)
    side_axis, side_sign, side_extent = _side_directions(
        V, he_face, he_from, he_to, side_half_lists, side_chart, chart_label,
        layout.chart_part, face_frame, twin, np.asarray(face_interface_axis, dtype=np.float64))
    _orient_slits(V, side_chart, side_corners, side_axis, side_sign, side_extent, side_offsets,
                  side_chain, chart_label, face_frame[layout.chart_first_face],
                  np.isin(np.arange(len(corners)), corner_of_vertex[middles]))

    sizes = np.array([len(r) for r in loop_side_lists], dtype=np.int64)
    loop_offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
    loop_offsets[1:] = np.cumsum(sizes)
    area = face_areas(V, F)
    return ChartComplex(
        face_chart=face_chart, chart_label=chart_label, chart_part=layout.chart_part,
        chart_area=np.bincount(face_chart, weights=area, minlength=layout.n_charts),
        corner_vertex=corners.astype(np.int64), side_chart=side_chart,
        side_corners=side_corners, side_axis=side_axis, side_sign=side_sign,
        side_extent=side_extent, side_offsets=side_offsets, side_chain=side_chain,
        loop_chart=np.asarray(loop_charts, dtype=np.int64), loop_offsets=loop_offsets,
        loop_sides=np.asarray([r for refs in loop_side_lists for r in refs], dtype=np.int64))


_LABEL_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")


def _orient_slits(V, side_chart, side_corners, side_axis, side_sign, side_extent, side_offsets,
                  side_chain, chart_label, chart_frame, is_middle):
    """Axis of every slit side: perpendicular to the chart side its outer end lies on.

    (A slit end that meets no plain side keeps the measured axis of the slit.)

    Updates ``side_axis``, ``side_sign`` and ``side_extent`` in place (both columns). The sign
    and extent are measured along that axis of the chart's frame (``chart_frame`` (c, 3, 3)).
    """
    slits = np.flatnonzero(side_chart[:, 0] == side_chart[:, 1])
    if len(slits) == 0:
        return
    plain = side_chart[:, 0] != side_chart[:, 1]
    for s in slits.tolist():
        chart = side_chart[s, 0]
        chain = V[side_chain[side_offsets[s]:side_offsets[s + 1]]]
        axis = side_axis[s, 0]
        for end in side_corners[s][np.argsort(is_middle[side_corners[s]], kind="stable")]:
            touching = np.flatnonzero(plain & (side_chart == chart).any(axis=1)
                                      & (side_corners == end).any(axis=1))
            if len(touching):
                other = touching[0]
                column = 0 if side_chart[other, 0] == chart else 1
                axis = 3 - chart_label[chart] // 2 - side_axis[other, column]
                break
        extent = float((chain[-1] - chain[0]) @ chart_frame[chart, axis])
        side_axis[s] = axis
        side_sign[s] = 1 if extent >= 0.0 else -1
        side_extent[s] = abs(extent)


def _side_directions(V, he_face, he_from, he_to, side_half_lists, side_chart, chart_label,
                     chart_part, face_frame, twin, face_interface_axis):
    """Axis, direction sign and measured extent of every side, in each adjacent chart's frame.

    The extent along an axis is the sum over the side's edges of the edge vector projected on
    that axis of the frame of the face on the chart's side of the edge, so blended frames are
    followed along the side. A side between two parts lies in the interface: in each part it
    runs along the axis perpendicular to its chart's label and to the part axis nearest the
    interface's normal (``face_interface_axis``), or, where that is the label axis or the
    normal is unknown, along the in-plane axis in which it extends most.
    """
    n_sides = len(side_half_lists)
    side_axis = np.zeros((n_sides, 2), dtype=np.int64)
    side_sign = np.ones((n_sides, 2), dtype=np.int64)
    side_extent = np.zeros((n_sides, 2))
    lengths = np.array([len(r) for r in side_half_lists])
    run = np.concatenate(side_half_lists)
    owner = np.repeat(np.arange(n_sides), lengths)
    edge_vec = V[he_to[run]] - V[he_from[run]]
    same_part = chart_part[side_chart[:, 0]] == chart_part[side_chart[:, 1]]
    per_column = []
    for faces in (he_face[run], he_face[twin[run]]):
        # (k, 3) projections of each edge on the three axes of the face's frame
        proj = np.einsum("kij,kj->ki", face_frame[faces], edge_vec)
        per_side = np.zeros((n_sides, 3))
        np.add.at(per_side, owner, proj)
        per_column.append(per_side)
    # a side inside one part has one direction: measured with the frames of both sides
    both = per_column[0] + per_column[1]
    for column in (0, 1):
        per_side = np.where(same_part[:, None], both, per_column[column])
        chart_axis = chart_label[side_chart[:, column]] // 2
        other_axis = chart_label[side_chart[:, 1 - column]] // 2
        within = 3 - chart_axis - other_axis
        # interface sides and slits: the in-plane axis along which the side extends most,
        # or for interface sides the one perpendicular to the interface normal
        candidates = np.abs(per_side).copy()
        candidates[np.arange(n_sides), chart_axis] = -1.0
        across = np.argmax(candidates, axis=1)
        first_face = he_face[run[np.concatenate([[0], np.cumsum(lengths)[:-1]])]]
        if column == 1:
            first_face = he_face[twin[run[np.concatenate([[0], np.cumsum(lengths)[:-1]])]]]
        normal = face_interface_axis[first_face]
        known = np.isfinite(normal).all(axis=1)
        cap = np.argmax(np.abs(np.einsum("sij,sj->si", face_frame[first_face],
                                         np.nan_to_num(normal))), axis=1)
        use_cap = ~same_part & known & (cap != chart_axis)
        across = np.where(use_cap, 3 - chart_axis - cap, across)
        slit = side_chart[:, 0] == side_chart[:, 1]
        axis = np.where(same_part & ~slit, within, across)
        if (same_part & ~slit & (chart_axis == other_axis)).any():
            bad = int(np.flatnonzero(same_part & ~slit & (chart_axis == other_axis))[0])
            raise LabelingError(
                f"charts {side_chart[bad].tolist()} meet along a boundary but have the same or "
                f"opposite labels ({_LABEL_NAMES[chart_label[side_chart[bad, 0]]]}, "
                f"{_LABEL_NAMES[chart_label[side_chart[bad, 1]]]}) near "
                f"{np.round(V[he_from[side_half_lists[bad][0]]], 4).tolist()}: "
                "the labeling is not a valid polycube")
        extent = per_side[np.arange(n_sides), axis] * np.where(same_part, 0.5, 1.0)
        side_axis[:, column] = axis
        side_sign[:, column] = np.where(extent >= 0.0, 1, -1)
        side_extent[:, column] = np.abs(extent)
    return side_axis, side_sign, side_extent

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Validity of a polycube labeling: invalid charts, boundaries, corners and turning points.

Rules (charts, boundaries and corners as in :mod:`core.segmentation.charts`):

- a chart with three or fewer boundaries is invalid;
- a boundary between opposite labels (e.g. +X / -X) of one part is invalid;
- the *axis* of a boundary between labels ``a`` and ``b`` of one part is the frame axis
  perpendicular to both (a +X/+Y boundary runs along Z);
- a corner is valid when, for every part that meets at it, none of the separating edges at the
  corner is invalid and their axes pair up or form one X, Y, Z group plus pairs (the counts of X,
  Y and Z edges are all even or all odd), except that edges of one axis alone are valid only as a
  plain pass-through of exactly two (:func:`corner_axes_valid`; the rule of the independent
  check, the validity-first polycube labeling work). The parity part always holds inside one part
  without opposite labels (around a vertex of degree ``D`` with ``n_k`` charts of axis ``k`` the
  count of axis ``k`` edges is ``D - 2 n_k``), but a fan alternating between two axes, e.g. +X, +Y,
  -X, -Y, gives ``D`` edges of the third axis: two boundary curves parallel to one axis would cross
  at the vertex, which no polycube realises, so the one-axis clause is what bites inside a part;
  the parity clause bites at part interfaces.

Interface rules (edges between two parts): the interface loops are the connected chains of edges
between one pair of parts; each loop's x-axis is the smallest-eigenvalue eigenvector of the
covariance of its vertices (the paper's Eq. 1 on the interface; the same axis the labeling's term 4
uses, :func:`core.segmentation.parts.interface_x_axis`). On each side an interface edge of a chart
with label direction ``d`` gets the axis of that side's frame nearest to ``d x x_interface``; an
interface boundary is invalid when a side's label direction is within 45 degrees of the interface
x-axis (the situation Eq. 3's term 4 forbids). A corner on an interface is judged per part with
those axes, so a boundary of part P that ends on the interface forms an X, Y, Z group with the two
interface edges on P's side, and the other side sees a plain pair.

Turning points (monotonicity): along a boundary of one part with axis ``k``, walk its vertex chain
and accumulate ``s`` = displacement projected on the frame's ``k`` axis (the frame of the face on
the edge's first side). A turning point is a vertex where ``s`` reverses by more than ``tau``
(hysteresis; default ``tau`` = mean edge length, so the zig-zag of a boundary that follows triangle
edges does not count) from its running extreme; the vertex at the extreme is the turning point.
Interface boundaries are not checked for monotonicity (they are planar cuts by construction).
A corner-free closed boundary is walked from its lowest point, and that point counts as a turning
point when the walk comes back down to it, so a closed loop of extent above ``tau`` along its axis
has at least two turning points.
"""
from dataclasses import dataclass, replace

import numpy as np

from core.compiled import keeps_interrupts, numba
from core.segmentation.charts import MeshTopology, boundary_walks, build_topology, extract_layout
from core.segmentation.parts import interface_pieces, interface_x_axis

COS_45 = float(np.sqrt(0.5))


@dataclass
class Validity:
    """Result of :func:`check_validity` (arrays for the repair loop plus a JSON report).

    layout : ChartLayout
    invalid_chart : (c,) bool
    invalid_boundary : (b,) bool
    boundary_reason : (b,) int8, 0 valid, 1 opposite labels, 2 label parallel to interface x-axis
    boundary_axis : (b,) int64 axis 0..2 of within-part boundaries, -1 opposite, -2 interface
    invalid_corners : (q,) int64 invalid corner vertices
    turning_points : (t, 2) int64 rows (boundary, vertex)
    report : dict (JSON-serialisable), see :func:`check_validity`
    """

    layout: object
    invalid_chart: np.ndarray
    invalid_boundary: np.ndarray
    boundary_reason: np.ndarray
    boundary_axis: np.ndarray
    invalid_corners: np.ndarray
    turning_points: np.ndarray
    report: dict

    @property
    def is_valid(self):
        return bool(self.report["valid"])

    @property
    def n_invalid(self):
        """Invalid charts + boundaries + corners."""
        r = self.report
        return (r["invalid_charts"]["count"] + r["invalid_boundaries"]["count"]
                + r["invalid_corners"]["count"])


def _label_direction(face_frame, faces, labels):
    sign = np.where(labels % 2 == 0, 1.0, -1.0)
    return face_frame[faces, labels // 2] * sign[:, None]


def _interface_side_axis(face_frame, face, label, ix):
    """Axis (0..2, or -1 if the label is parallel to ``ix``) of interface edges seen from ``face``."""
    d = _label_direction(face_frame, face, label)
    parallel = np.abs((d * ix).sum(axis=1)) > COS_45
    t = np.cross(d, ix)
    local = np.abs(np.einsum("fij,fj->fi", face_frame[face], t))
    local[np.arange(len(face)), label // 2] = -1.0
    axis = np.argmax(local, axis=1)
    return np.where(parallel, -1, axis).astype(np.int64)


@keeps_interrupts
def _turning_points(V, topology, layout, face_frame, boundary_axis, tau, which=None):
    """(t, 2) int64 rows (boundary, vertex) of the turning points (module docstring); only the
    boundaries flagged in ``which`` ((b,) bool) are walked when it is given."""
    w = boundary_walks(topology, layout, which)
    return _turning_kernel(np.ascontiguousarray(V, dtype=np.float64), topology.edge_faces,
                           np.ascontiguousarray(face_frame, dtype=np.float64), w.vertices,
                           w.edges, w.offsets, w.length, w.closed, w.walked,
                           np.ascontiguousarray(boundary_axis, dtype=np.int64), float(tau))


@numba.njit(cache=True, nogil=True)
def _turning_kernel(V, edge_faces, face_frame, chain_v, chain_e, offsets, length, closed,
                    walked, boundary_axis, tau):
    """:func:`_turning_points` on the walks of :func:`core.segmentation.charts.boundary_walks`
    (its arrays): the displacement along each walked boundary of axis ``k >= 0`` and two or
    more edges, projected on the ``k`` axis of the frame of each edge's first face, summed
    from the start (a loop from its lowest point), and the hysteresis walk over the sums."""
    rows = []
    for b in range(len(offsets)):
        k = boundary_axis[b]
        n = length[b]
        if not walked[b] or k < 0 or n < 2:
            continue
        v0 = offsets[b] + b
        e0 = offsets[b]
        step = np.empty(n)
        for i in range(n):
            a, c, f = chain_v[v0 + i], chain_v[v0 + i + 1], edge_faces[chain_e[e0 + i], 0]
            acc = (V[c, 0] - V[a, 0]) * face_frame[f, k, 0]
            acc += (V[c, 1] - V[a, 1]) * face_frame[f, k, 1]
            acc += (V[c, 2] - V[a, 2]) * face_frame[f, k, 2]
            step[i] = acc
        verts = chain_v[v0:v0 + n + 1].copy()
        if closed[b]:
            # start a loop at its lowest point so the turn there is seen when the walk closes
            low, lowest, total = 0, 0.0, 0.0
            for i in range(n - 1):
                total += step[i]
                if total < lowest:
                    low, lowest = i + 1, total
            step = np.concatenate((step[low:], step[:low]))
            ring = verts[:n]
            verts = np.concatenate((ring[low:], ring[:low], ring[low:low + 1]))
        found = len(rows)
        direction, ext, ext_i = 0, 0.0, 0
        lo = hi = 0.0
        si = 0.0
        for i in range(n + 1):
            if i:
                si += step[i - 1]
            if direction == 0:
                lo, hi = min(lo, si), max(hi, si)
                if si - lo > tau:
                    direction, ext, ext_i = 1, si, i
                elif hi - si > tau:
                    direction, ext, ext_i = -1, si, i
            elif direction * (si - ext) > 0:
                ext, ext_i = si, i
            elif direction * (ext - si) > tau:
                rows.append((b, verts[ext_i]))
                direction, ext, ext_i = -direction, si, i
        if closed[b] and len(rows) > found and direction < 0:
            rows.append((b, verts[0]))
    out = np.empty((len(rows), 2), dtype=np.int64)
    for i in range(len(rows)):
        out[i, 0], out[i, 1] = rows[i]
    return out


def _example_point(V, F, face):
    return [float(x) for x in V[F[face]].mean(axis=0)]


def edge_interface_axes(V, topology, face_part):
    """(e, 3) float64 x-axis of the interface of every edge between two parts (0 elsewhere).

    The interfaces are :func:`core.segmentation.parts.interface_pieces` of ``topology``'s edges
    and their axis :func:`core.segmentation.parts.interface_x_axis` of their vertices: the
    pieces and the axis the frames and the labeling's Eq. 3 term 4 use.

    Parameters
    ----------
    V : (n, 3) float64 vertices.
    topology : MeshTopology.
    face_part : (m,) int part of each face.
    """
    V = np.asarray(V, dtype=np.float64)
    edge_ix = np.zeros((len(topology.edges), 3))
    for _, index in interface_pieces(topology.edges, topology.edge_faces, face_part,
                                     topology.n_vertices):
        edge_ix[index] = interface_x_axis(V[np.unique(topology.edges[index])])
    return edge_ix


def corner_axes_valid(counts):
    """Corner rule on the axis counts of the separating edges at a corner (one part's view).

    Parameters
    ----------
    counts : (g, 4) int, per corner (and part) the number of separating edges of axis X, Y, Z
        and of edges without a valid axis (opposite labels, label parallel to an interface).

    Returns
    -------
    (g,) bool, True where valid: no axis-less edge, and either exactly two edges of a single axis
    (a pass-through) or at least two axes with X, Y, Z counts all even or all odd (pairs, or one
    X, Y, Z group plus pairs). One axis alone one, three or more times is invalid.
    """
    counts = np.asarray(counts, dtype=np.int64).reshape(-1, 4)
    axes = counts[:, :3]
    parity = axes % 2
    paired = (parity == parity[:, :1]).all(axis=1)
    one_axis = (axes > 0).sum(axis=1) == 1
    return (counts[:, 3] == 0) & np.where(one_axis, axes.max(axis=1) == 2, paired)


def _judge(topology, face_part, face_label, face_frame, edge_ix):
    """Layout and invalid items of a labeling (the rules of the module docstring).

    ``edge_ix`` : (e, 3) interface x-axis per edge of ``topology`` (:func:`edge_interface_axes`).
    Returns a dict with ``layout``, ``boundary_axis``, ``reason``, ``invalid_chart``,
    ``invalid_corners`` and the corner incidences ``inc_v``, ``inc_part``, ``inc_axis``.
    """
    lay = extract_layout(topology, face_part, face_label)
    ef = topology.edge_faces

    # boundaries
    boundary_axis = _boundary_axes(lay)
    reason = np.where(boundary_axis == -1, 1, 0).astype(np.int8)

    # per separating edge and side: the axis seen from that side's part
    sep = lay.sep_edges
    f0, f1 = ef[sep, 0], ef[sep, 1]
    is_iface = face_part[f0] != face_part[f1]
    side_axis = np.empty((len(sep), 2), dtype=np.int64)
    inner_axis = boundary_axis[lay.sep_boundary]
    side_axis[:, 0] = inner_axis
    side_axis[:, 1] = inner_axis
    if is_iface.any():
        fi0, fi1, ix = f0[is_iface], f1[is_iface], edge_ix[sep[is_iface]]
        side_axis[is_iface, 0] = _interface_side_axis(face_frame, fi0, face_label[fi0], ix)
        side_axis[is_iface, 1] = _interface_side_axis(face_frame, fi1, face_label[fi1], ix)
        bad_edge = (side_axis[is_iface] < 0).any(axis=1)
        bad_b = np.unique(lay.sep_boundary[is_iface][bad_edge])
        reason[bad_b] = 2

    # charts
    invalid_chart = lay.chart_boundary_count <= 3

    # corners, judged per part meeting at the vertex
    ev = topology.edges[sep]
    inc_v, inc_part, inc_axis = [], [], []
    for end in (0, 1):
        v = ev[:, end]
        at_corner = lay.vertex_sep_degree[v] >= 3
        for side, fs in ((0, f0), (1, f1)):
            keep = at_corner & (is_iface | (side == 0))
            inc_v.append(v[keep])
            inc_part.append(face_part[fs[keep]])
            inc_axis.append(side_axis[keep, side])
    inc_v = np.concatenate(inc_v)
    inc_part = np.concatenate(inc_part)
    inc_axis = np.concatenate(inc_axis)
    n_parts = int(face_part.max()) + 1 if len(face_part) else 1
    key, group = np.unique(inc_v * n_parts + inc_part, return_inverse=True)
    slot = group.reshape(-1) * 4 + np.where(inc_axis >= 0, inc_axis, 3)
    counts = np.bincount(slot, minlength=4 * len(key)).reshape(len(key), 4)
    group_ok = corner_axes_valid(counts)
    invalid_corners = np.unique(key[~group_ok] // n_parts)
    return {"layout": lay, "boundary_axis": boundary_axis, "reason": reason,
            "invalid_chart": invalid_chart, "invalid_corners": invalid_corners,
            "inc_v": inc_v, "inc_part": inc_part, "inc_axis": inc_axis}


def sub_topology(topology, faces):
    """Topology of the submesh made of ``faces`` (sorted (s,) int64), global vertex ids kept.

    Returns
    -------
    sub : MeshTopology of the submesh (faces numbered 0..s-1 in the order of ``faces``; edges
        whose other face lies outside are open, ``-1``).
    edge_ids : (e_s,) int64 global edge of each submesh edge.
    """
    m = len(topology.face_edges)
    local = np.full(m + 1, -1, dtype=np.int64)
    local[faces] = np.arange(len(faces))
    fe = topology.face_edges[faces]
    used = np.zeros(len(topology.edges), dtype=bool)
    used[fe] = True
    edge_ids = np.flatnonzero(used)
    edge_local = np.cumsum(used) - 1
    edges = topology.edges[edge_ids]
    edge_faces = local[topology.edge_faces[edge_ids]]
    open_first = edge_faces[:, 0] < 0
    edge_faces[open_first] = edge_faces[open_first][:, ::-1]
    face_edges = edge_local[fe]
    neighbours = local[topology.neighbours[faces]]
    sub = MeshTopology(edges, edge_faces, face_edges, neighbours, topology.n_vertices)
    return sub, edge_ids


def local_invalid_count(F, topology, face_part, face_label, face_frame, edge_ix, faces,
                        vertex_mask):
    """Invalid items touching ``vertex_mask``, judged on the submesh ``faces`` only.

    Exact when ``faces`` holds every face of every chart that has a vertex in ``vertex_mask`` and
    every face around each vertex of those charts (then those charts, their boundaries and the
    corners in ``vertex_mask`` are the same as on the whole mesh). The difference of this count
    between two labelings that differ only on faces whose vertices are all in ``vertex_mask`` is
    the difference of their :attr:`Validity.n_invalid`.

    Parameters
    ----------
    F : (m, 3) int64 faces.
    topology : MeshTopology of the whole mesh.
    face_part, face_label : (m,) int64.
    face_frame : (m, 3, 3) float64.
    edge_ix : (e, 3) float64, :func:`edge_interface_axes`.
    faces : (s,) int64 sorted submesh faces.
    vertex_mask : (n,) bool.

    Returns
    -------
    (charts, boundaries, corners, opposite) : int counts of invalid charts with a vertex in
    ``vertex_mask``, invalid boundaries with a vertex there, invalid corners there, and of those
    boundaries the ones between opposite labels.
    """
    sub, edge_ids = sub_topology(topology, faces)
    j = _judge(sub, face_part[faces], face_label[faces], face_frame[faces], edge_ix[edge_ids])
    return _local_invalid(F, sub, j, faces, vertex_mask)


def counts_near(F, topology, validity, vertex_mask):
    """The counts of :func:`local_counts` read off a whole-mesh judgement.

    Under the condition of :func:`local_invalid_count` the submesh judges the items touching
    ``vertex_mask`` (and walks the boundaries with an edge there) as the whole mesh does, so for
    the labeling that ``validity`` judged the counts follow from it without judging again.

    Parameters
    ----------
    F : (m, 3) int64 faces; topology : MeshTopology of the whole mesh.
    validity : Validity of the labeling on the whole mesh (:func:`check_validity`).
    vertex_mask : (n,) bool.

    Returns
    -------
    (charts, boundaries, corners, opposite, turning) : int, as :func:`local_counts`;
    ``turning`` is None when ``validity`` was judged without turning points.
    """
    j = {"layout": validity.layout, "invalid_chart": validity.invalid_chart,
         "reason": validity.boundary_reason, "invalid_corners": validity.invalid_corners}
    counts = _local_invalid(F, topology, j, None, vertex_mask)
    if validity.report["turning_points"]["count"] is None:
        return counts + (None,)
    near = boundaries_at(topology, validity.layout, vertex_mask)
    return counts + (int(near[validity.turning_points[:, 0]].sum()),)


def boundaries_at(topology, layout, vertex_mask):
    """(b,) bool boundaries of ``layout`` with an edge at ``vertex_mask``."""
    ev = topology.edges[layout.sep_edges]
    near = np.zeros(layout.n_boundaries, dtype=bool)
    near[layout.sep_boundary[vertex_mask[ev[:, 0]] | vertex_mask[ev[:, 1]]]] = True
    return near


def _local_invalid(F, sub, j, faces, vertex_mask):
    """The counts of :func:`local_invalid_count` from the submesh judgement ``j`` (of
    :func:`_judge` on ``sub``, the topology of ``faces``; ``faces`` None: the whole mesh)."""
    lay = j["layout"]
    fv = F if faces is None else F[faces]
    touch_face = vertex_mask[fv[:, 0]] | vertex_mask[fv[:, 1]] | vertex_mask[fv[:, 2]]
    charts = np.zeros(lay.n_charts, dtype=bool)
    charts[lay.face_chart[touch_face]] = True
    bnd = boundaries_at(sub, lay, vertex_mask)
    reason = j["reason"]
    return (int((charts & j["invalid_chart"]).sum()), int((bnd & (reason > 0)).sum()),
            int(vertex_mask[j["invalid_corners"]].sum()), int((bnd & (reason == 1)).sum()))


def local_counts(V, F, topology, face_part, face_label, face_frame, edge_ix, faces, vertex_mask,
                 tau, sub=None, max_invalid=None):
    """:func:`local_invalid_count` and the turning points on the boundaries with an edge at
    ``vertex_mask``, from one submesh layout.

    Exact under the condition of :func:`local_invalid_count`: those boundaries are then whole in
    the submesh and walked as on the whole mesh; a boundary without an edge at ``vertex_mask`` is
    the same in two labelings that differ only on faces whose vertices are all in ``vertex_mask``
    (its edges' faces and its vertices' separating edges are unchanged), so the difference of this
    count between such labelings is the difference of their whole-mesh turning-point counts.

    Parameters
    ----------
    V : (n, 3) float64; the other parameters as in :func:`local_invalid_count`.
    tau : float, the hysteresis of :func:`check_validity` (mesh units).
    sub : optional ``sub_topology(topology, faces)``, for judging several labelings on one zone.
    max_invalid : int, optional; when the invalid charts + boundaries + corners exceed it, the
        turning points are not walked and ``turning`` is None.

    Returns
    -------
    (charts, boundaries, corners, opposite, turning) : int counts, the first four those of
    :func:`local_invalid_count`.
    """
    sub, edge_ids = sub_topology(topology, faces) if sub is None else sub
    j = _judge(sub, face_part[faces], face_label[faces], face_frame[faces], edge_ix[edge_ids])
    counts = _local_invalid(F, sub, j, faces, vertex_mask)
    if max_invalid is not None and sum(counts[:3]) > max_invalid:
        return counts + (None,)
    lay = j["layout"]
    # a boundary without an edge at vertex_mask is the same in both labelings: not walked
    which = boundaries_at(sub, lay, vertex_mask)
    tp = _turning_points(V, sub, lay, face_frame[faces], j["boundary_axis"], tau, which)
    return counts + (len(tp),)


def _boundary_axes(lay):
    """(b,) int64 axis 0..2 of each within-part boundary, -1 between opposite labels, -2 between
    parts (the ``boundary_axis`` of :class:`Validity`)."""
    ca, cb = lay.boundary_charts[:, 0], lay.boundary_charts[:, 1]
    la, lb = lay.chart_label[ca], lay.chart_label[cb]
    same_part = lay.chart_part[ca] == lay.chart_part[cb]
    opposite = same_part & (la // 2 == lb // 2)
    return np.where(same_part, np.where(opposite, -1, 3 - la // 2 - lb // 2), -2)


def check_validity(V, F, face_part, face_label, face_frame, topology=None, turning=True,
                   turning_tolerance=None, max_examples=5, edge_interface_axis=None):
    """Judge a labeling by the polycube validity rules (see module docstring).

    Parameters
    ----------
    V : (n, 3) float64 vertices.
    F : (m, 3) int faces.
    face_part : (m,) int part of each face.
    face_label : (m,) int label 0..5 of each face (+X, -X, +Y, -Y, +Z, -Z of its frame).
    face_frame : (m, 3, 3) float64 rows x, y, z of each face's frame (world coordinates).
    topology : MeshTopology, optional (computed from ``F`` when omitted).
    turning : bool, also find turning points (walks every boundary; off inside repair loops).
    turning_tolerance : float, hysteresis ``tau`` in mesh units (default mean edge length).
    max_examples : int, examples per category in the report.
    edge_interface_axis : (e, 3) float64, optional interface x-axes per edge of ``topology``
        (:func:`edge_interface_axes`, which computes them when omitted; they depend on the parts
        only, so loops over labelings pass them once).

    Returns
    -------
    Validity
        ``report`` holds ``valid`` (no invalid charts, boundaries or corners), ``monotone``,
        ``charts``, ``boundaries``, ``corners`` and, for ``invalid_charts``,
        ``invalid_boundaries``, ``invalid_corners`` and ``turning_points``, a ``count`` and a few
        ``examples`` (ids, labels, an example face or vertex and its coordinates); for boundaries
        and corners also ``at_interfaces``, how many of them are judged by the interface rules
        (a label parallel to the interface x-axis; a corner on a part interface), which a check
        that treats each part as its own polycube without the interface frames does not see.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    face_label = np.asarray(face_label, dtype=np.int64)
    face_frame = np.asarray(face_frame, dtype=np.float64)
    if topology is None:
        topology = build_topology(F, len(V))
    if edge_interface_axis is None:
        edge_interface_axis = edge_interface_axes(V, topology, face_part)
    j = _judge(topology, face_part, face_label, face_frame, edge_interface_axis)
    lay, boundary_axis, reason = j["layout"], j["boundary_axis"], j["reason"]
    invalid_chart, invalid_corners = j["invalid_chart"], j["invalid_corners"]
    inc_v, inc_part, inc_axis = j["inc_v"], j["inc_part"], j["inc_axis"]
    invalid_boundary = reason > 0
    ca, cb = lay.boundary_charts[:, 0], lay.boundary_charts[:, 1]
    la, lb = lay.chart_label[ca], lay.chart_label[cb]

    names = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
    chart_ex = []
    for c in np.flatnonzero(invalid_chart)[:max_examples]:
        f = int(lay.chart_first_face[c])
        chart_ex.append({"chart": int(c), "part": int(lay.chart_part[c]),
                         "label": names[lay.chart_label[c]], "faces": int(lay.chart_size[c]),
                         "boundaries": int(lay.chart_boundary_count[c]), "face": f,
                         "point": _example_point(V, F, f)})
    bnd_ex = []
    reasons = {1: "opposite_labels", 2: "label_parallel_to_interface"}
    for b in np.flatnonzero(invalid_boundary)[:max_examples]:
        e = int(lay.boundary_first_edge[b])
        bnd_ex.append({"boundary": int(b), "charts": [int(ca[b]), int(cb[b])],
                       "labels": [names[la[b]], names[lb[b]]], "reason": reasons[int(reason[b])],
                       "edges": int(lay.boundary_size[b]), "edge": e,
                       "point": [float(x) for x in V[topology.edges[e]].mean(axis=0)]})
    corner_ex = []
    for v in invalid_corners[:max_examples]:
        sel = inc_v == v
        corner_ex.append({"vertex": int(v), "point": [float(x) for x in V[v]],
                          "edges": int(lay.vertex_sep_degree[v]),
                          "axes": ["XYZ?"[a] for a in inc_axis[sel].tolist()],
                          "parts": sorted({int(p) for p in inc_part[sel].tolist()})})
    n_ic, n_ib, n_iq = int(invalid_chart.sum()), int(invalid_boundary.sum()), len(invalid_corners)
    ef = topology.edge_faces[lay.sep_edges]
    on_iface = np.zeros(topology.n_vertices, dtype=bool)
    on_iface[topology.edges[lay.sep_edges[face_part[ef[:, 0]] != face_part[ef[:, 1]]]]] = True
    report = {
        "valid": n_ic + n_ib + n_iq == 0,
        "monotone": None,
        "charts": lay.n_charts,
        "boundaries": lay.n_boundaries,
        "corners": len(lay.corners),
        "invalid_charts": {"count": n_ic, "examples": chart_ex},
        "invalid_boundaries": {"count": n_ib, "examples": bnd_ex,
                               "at_interfaces": int((reason == 2).sum())},
        "invalid_corners": {"count": n_iq, "examples": corner_ex,
                            "at_interfaces": int(on_iface[invalid_corners].sum())},
        "turning_points": {"count": None, "examples": [], "tolerance": None},
    }
    validity = Validity(lay, invalid_chart, invalid_boundary, reason, boundary_axis,
                        invalid_corners, np.zeros((0, 2), dtype=np.int64), report)
    if not turning:
        return validity
    return with_turning_points(V, topology, face_frame, validity, turning_tolerance, max_examples)


def with_turning_points(V, topology, face_frame, validity, turning_tolerance=None,
                        max_examples=5):
    """``validity`` (of :func:`check_validity`) with its turning points found and reported.

    Parameters
    ----------
    V : (n, 3) float64 vertices; topology : MeshTopology; face_frame : (m, 3, 3) float64.
    validity : Validity judged without turning points (``turning=False``).
    turning_tolerance : float, hysteresis ``tau`` in mesh units (default mean edge length).
    max_examples : int, examples in the report.

    Returns
    -------
    Validity with ``turning_points`` and the report's ``monotone`` and ``turning_points``.
    """
    V = np.asarray(V, dtype=np.float64)
    tau = turning_tolerance
    if tau is None:
        tau = float(np.linalg.norm(V[topology.edges[:, 0]] - V[topology.edges[:, 1]],
                                   axis=1).mean()) if len(topology.edges) else 0.0
    tau = float(tau)
    tp = _turning_points(V, topology, validity.layout, np.asarray(face_frame, dtype=np.float64),
                         validity.boundary_axis, tau)
    report = dict(validity.report)
    report["monotone"] = len(tp) == 0
    report["turning_points"] = {
        "count": len(tp),
        "examples": [{"boundary": int(b), "vertex": int(v), "point": [float(x) for x in V[v]]}
                     for b, v in tp[:max_examples].tolist()],
        "tolerance": tau}
    return replace(validity, turning_points=tp, report=report)

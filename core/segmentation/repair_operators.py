# SPDX-License-Identifier: LGPL-2.1-or-later
"""The repair's local operators on a polycube labeling, and its candidate labelings.

Each operator takes the current labels (``(m,) int64``, 0..5) and their judgement (a
:class:`core.segmentation.validity.Validity`), changes the labels of some faces and returns a
:class:`Relabel`: the new labels and the number of invalid items it worked on. The operators and
the order the repair tries them in are described in :mod:`core.segmentation.repair`; the
candidate generators (:func:`chart_candidates`, :func:`joint_merges`) return named
:class:`Trial` labelings for one invalid chart, which the repair scores.
"""
from dataclasses import dataclass

import numpy as np

from core.segmentation.charts import OPPOSITE
from core.segmentation.labeling import hbecvt_sweeps, label_vectors
from core.segmentation.validity import COS_45


@dataclass(frozen=True)
class Relabel:
    """What one operator did.

    labels : (m,) int64 new labels 0..5 (a copy; the input labels are not modified).
    items : int, the invalid items (boundaries, charts, corners) it worked on.
    """

    labels: np.ndarray
    items: int


@dataclass(frozen=True)
class Trial:
    """A named candidate labeling for one invalid chart (not yet judged).

    name : str, what it does (``merge_into_3``, ``grow_ring``, ...; in the repair's report).
    labels : (m,) int64 labels 0..5.
    """

    name: str
    labels: np.ndarray


@dataclass(frozen=True)
class OneAxisCorners:
    """Invalid corners whose separating edges all share one axis.

    vertices : (k,) int64 corner vertices.
    axes : (k,) int64 the common axis of each (0 x, 1 y, 2 z).
    """

    vertices: np.ndarray
    axes: np.ndarray


def chart_costs(cost, face_chart, n_charts):
    """(c, 6) summed label cost of every chart."""
    return np.stack([np.bincount(face_chart, weights=cost[:, l], minlength=n_charts)
                     for l in range(6)], axis=1)


def faces_at_vertices(F, vertex_mask):
    """(m,) bool faces with a corner in ``vertex_mask`` ((n,) bool)."""
    return vertex_mask[F[:, 0]] | vertex_mask[F[:, 1]] | vertex_mask[F[:, 2]]


def split_opposite_boundaries(F, topology, val, labels, cost):
    """Strip insertion at every opposite-label boundary (operator 1 of the repair).

    The faces of both charts touching the boundary's vertices form a strip (a chart joins the
    strip of the first, lowest-id, opposite boundary it lies on); the strip takes the label of
    another axis of least summed cost, avoiding the opposites of the labels touching it from
    outside where it can.

    Parameters
    ----------
    F : (m, 3) int64; topology : MeshTopology; val : Validity of ``labels``.
    labels : (m,) int64; cost : (m, 6) float64 ``||n - c_l||^2``.

    Returns
    -------
    Relabel; ``items`` is the number of strips.
    """
    lay = val.layout
    bad = np.flatnonzero(val.boundary_reason == 1)
    edge_bad = np.isin(lay.sep_boundary, bad)
    vmask = np.zeros(topology.n_vertices, dtype=bool)
    vmask[topology.edges[lay.sep_edges[edge_bad]].reshape(-1)] = True
    charts = lay.boundary_charts[bad]
    chart_of_b = np.full(lay.n_charts, -1, dtype=np.int64)
    for col in (1, 0):
        chart_of_b[charts[::-1, col]] = bad[::-1]
    strip_b = chart_of_b[lay.face_chart]
    in_strip = faces_at_vertices(F, vmask) & (strip_b >= 0)
    faces = np.flatnonzero(in_strip)
    group = strip_b[faces]
    new = labels.copy()
    groups, inv = np.unique(group, return_inverse=True)
    gcost = chart_costs(cost[faces], inv.reshape(-1), len(groups))
    axis_ab = lay.chart_label[lay.boundary_charts[groups, 0]] // 2
    allowed = np.ones((len(groups), 6), dtype=bool)
    allowed[np.arange(len(groups)), 2 * axis_ab] = False
    allowed[np.arange(len(groups)), 2 * axis_ab + 1] = False
    # labels touching the strip from outside: avoid their opposites
    nb = topology.neighbours[faces]
    outside = (nb >= 0) & ~in_strip[np.maximum(nb, 0)]
    touch = np.zeros((len(groups), 6), dtype=bool)
    touch[np.repeat(inv, 3)[outside.reshape(-1)], labels[nb[outside]]] = True
    soft = allowed & ~touch[:, OPPOSITE]
    use = np.where(soft.any(axis=1)[:, None], soft, allowed)
    choice = np.argmin(np.where(use, gcost, np.inf), axis=1)
    new[faces] = choice[inv]
    return Relabel(new, len(groups))


def relabel_interface_parallel(F, topology, val, labels, cost, face_part, face_frame, iface_pen,
                               edge_ix):
    """Relabel faces whose label is parallel to a part interface's x-axis (operator 2).

    Two sets of faces change: faces next to the invalid interface boundaries whose label carries
    Eq. 3's interface penalty, and the faces on interface edges whose label direction lies within
    45 degrees of that edge's loop axis (the rule of
    :func:`core.segmentation.validity.check_validity`). Each takes its least-cost label that is
    neither penalised nor within 45 degrees of the axis.

    Parameters
    ----------
    F, topology, val, labels, cost : as :func:`split_opposite_boundaries`.
    face_part : (m,) int64; face_frame : (m, 3, 3) float64.
    iface_pen : (m, 6) float64 Eq. 3 interface penalty of each label
        (:func:`core.segmentation.labeling.interface_penalty`).
    edge_ix : (e, 3) float64 interface x-axis of each edge
        (:func:`core.segmentation.validity.edge_interface_axes`).

    Returns
    -------
    Relabel; ``items`` is the number of invalid interface boundaries.
    """
    lay = val.layout
    m = len(F)
    bad = np.flatnonzero(val.boundary_reason == 2)
    edge_bad = np.isin(lay.sep_boundary, bad)
    vmask = np.zeros(topology.n_vertices, dtype=bool)
    vmask[topology.edges[lay.sep_edges[edge_bad]].reshape(-1)] = True
    forbid = iface_pen > 0
    sep = lay.sep_edges[edge_bad]
    sides = topology.edge_faces[sep]
    iface = face_part[sides[:, 0]] != face_part[sides[:, 1]]
    faces_e = sides[iface].reshape(-1)
    ix = np.repeat(edge_ix[sep[iface]], 2, axis=0)
    dirs = label_vectors(face_frame[faces_e])
    par = np.abs(np.einsum("fld,fd->fl", dirs, ix)) > COS_45
    np.logical_or.at(forbid, faces_e, par)
    wrong = forbid[np.arange(m), labels] & faces_at_vertices(F, vmask)
    faces = np.flatnonzero(wrong)
    new = labels.copy()
    new[faces] = np.argmin(cost[faces] + 1e3 * forbid[faces], axis=1)
    return Relabel(new, len(bad))


def merge_charts(val, labels, cost, which):
    """Merge the charts ``which`` into a neighbouring label (operator 3, in batches).

    Smallest first, an independent set (no two chosen charts touch): each chart takes the
    neighbouring chart label of its part of least summed cost among those not opposite to another
    label around it (else the least-cost neighbour label).

    Parameters
    ----------
    val : Validity of ``labels``; labels : (m,) int64; cost : (m, 6) float64.
    which : (c,) bool charts to merge.

    Returns
    -------
    Relabel; ``items`` is the number of charts merged.
    """
    lay = val.layout
    bad = np.flatnonzero(which)
    order = bad[np.lexsort((bad, lay.chart_size[bad]))]
    nbm = lay.chart_neighbours
    ccost = chart_costs(cost, lay.face_chart, lay.n_charts)
    blocked = np.zeros(lay.n_charts, dtype=bool)
    target = np.full(lay.n_charts, -1, dtype=np.int64)
    indptr, indices = nbm.indptr, nbm.indices
    for c in order.tolist():
        if blocked[c]:
            continue
        nbrs = indices[indptr[c]:indptr[c + 1]]
        nbrs = nbrs[lay.chart_part[nbrs] == lay.chart_part[c]]
        if len(nbrs) == 0:
            continue
        nl = np.unique(lay.chart_label[nbrs])
        ok = nl[~np.isin(OPPOSITE[nl], nl)]
        cand = ok if len(ok) else nl
        target[c] = cand[np.argmin(ccost[c, cand])]
        blocked[c] = True
        blocked[indices[indptr[c]:indptr[c + 1]]] = True
    chosen = np.flatnonzero(target >= 0)
    new = labels.copy()
    sel = target[lay.face_chart]
    move = sel >= 0
    new[move] = sel[move]
    return Relabel(new, len(chosen))


def one_axis_corners(topology, val):
    """Invalid corners whose separating edges all have one and the same axis (e.g. a fan
    +X, +Y, -X, -Y around the vertex: four edges along Z), and that axis.

    Returns
    -------
    OneAxisCorners
    """
    lay = val.layout
    ev = topology.edges[lay.sep_edges]
    axis = val.boundary_axis[lay.sep_boundary]
    v = np.concatenate([ev[:, 0], ev[:, 1]])
    a = np.concatenate([axis, axis])
    at = np.isin(v, val.invalid_corners)
    v, a = v[at], a[at]
    lo = np.full(topology.n_vertices, 9, dtype=np.int64)
    hi = np.full(topology.n_vertices, -9, dtype=np.int64)
    np.minimum.at(lo, v, a)
    np.maximum.at(hi, v, a)
    corners = val.invalid_corners
    one = (lo[corners] == hi[corners]) & (lo[corners] >= 0)
    return OneAxisCorners(corners[one], lo[corners[one]])


def insert_one_axis_charts(F, topology, labels, face_part, cost, corners, rings=2):
    """Insert a chart of each corner's common axis (operator 4).

    The faces of the corner's part within ``rings`` vertex rings of each corner take that axis'
    label of least summed cost, so the charts that met at a point (pairwise opposite across it)
    now each share a boundary with the new chart, whose corners are X, Y, Z groups.

    Parameters
    ----------
    F : (m, 3) int64; topology : MeshTopology; labels : (m,) int64; face_part : (m,) int64.
    cost : (m, 6) float64; corners : OneAxisCorners (:func:`one_axis_corners`).
    rings : int, vertex rings around each corner.

    Returns
    -------
    Relabel; ``items`` is the number of corners.
    """
    new = labels.copy()
    for v, k in zip(corners.vertices.tolist(), corners.axes.tolist()):
        vmask = np.zeros(topology.n_vertices, dtype=bool)
        vmask[v] = True
        for _ in range(rings):
            vmask[F[faces_at_vertices(F, vmask)]] = True
        part_of_corner = face_part[np.flatnonzero(F == v)[0] // 3]
        faces = np.flatnonzero(faces_at_vertices(F, vmask) & (face_part == part_of_corner))
        plus, minus = cost[faces, 2 * k].sum(), cost[faces, 2 * k + 1].sum()
        new[faces] = 2 * k if plus <= minus else 2 * k + 1
    return Relabel(new, len(corners.vertices))


def relabel_corner_faces(F, topology, val, labels, face_part):
    """The faces around each invalid corner take the label of their largest neighbouring chart
    of their part, where it is larger than their own (operator 5).

    Returns
    -------
    Relabel; ``items`` is the number of faces relabelled.
    """
    lay = val.layout
    vmask = np.zeros(topology.n_vertices, dtype=bool)
    vmask[val.invalid_corners] = True
    faces = np.flatnonzero(faces_at_vertices(F, vmask))
    new = labels.copy()
    size = lay.chart_size
    nb = topology.neighbours[faces]
    okn = (nb >= 0) & (face_part[np.maximum(nb, 0)] == face_part[faces][:, None])
    nb_chart = np.where(okn, lay.face_chart[np.maximum(nb, 0)], -1)
    nb_size = np.where(okn, size[np.maximum(nb_chart, 0)], -1)
    own = size[lay.face_chart[faces]]
    best = np.argmax(nb_size, axis=1)
    big = nb_size[np.arange(len(faces)), best] > own
    f = faces[big]
    new[f] = lay.chart_label[nb_chart[big, best[big]]]
    return Relabel(new, int(big.sum()))


def boundary_faces(topology, face_part, labels):
    """(m,) bool faces with an edge neighbour in another chart (other label or other part)."""
    tn = topology.neighbours
    ok = tn >= 0
    other = np.maximum(tn, 0)
    diff = ok & ((labels[other] != labels[:, None]) | (face_part[other] != face_part[:, None]))
    return diff[:, 0] | diff[:, 1] | diff[:, 2]


def smooth_boundaries(labels, active, unary, nb, colour, lam, penalty):
    """HBECVT sweeps on the ``active`` faces (those next to separating edges), labels limited to
    the labels of each face's neighbours: (m,) int64 labels."""
    has = nb >= 0
    present = np.zeros((len(labels), 6), dtype=bool)
    rows = np.repeat(np.arange(len(labels)), nb.shape[1])[has.reshape(-1)]
    present[rows, labels[nb[has]]] = True
    present[np.arange(len(labels)), labels] = True
    restricted = np.where(present, unary, unary + 4.0 * penalty)
    out, _ = hbecvt_sweeps(restricted, nb, labels, colour, lam, penalty, max_sweeps=3,
                           active=active)
    return out.astype(np.int64)


def local_resegment(labels, unary, nb, colour, region, lam, penalty):
    """Re-run the HBECVT sweeps inside ``region`` from nearest-direction labels with ``lam``:
    (m,) int64 labels."""
    start = labels.copy()
    start[region] = np.argmin(unary[region], axis=1)
    out, _ = hbecvt_sweeps(unary, nb, start, colour, lam, penalty, max_sweeps=50, active=region)
    return out.astype(np.int64)


def same_part_neighbours(layout, chart):
    """(k,) int64 the charts next to ``chart`` in its own part."""
    nbrs = layout.chart_neighbours[chart].indices
    return nbrs[layout.chart_part[nbrs] == layout.chart_part[chart]]


def neighbour_merges(layout, labels, chart):
    """``[(label, labels)]``: ``labels`` ((m,) int64) with the faces of ``chart`` given each
    label of its neighbouring charts in its part, one labeling per label."""
    in_chart = layout.face_chart == chart
    merges = []
    for lab in np.unique(layout.chart_label[same_part_neighbours(layout, chart)]).tolist():
        cand = labels.copy()
        cand[in_chart] = lab
        merges.append((lab, cand))
    return merges


def chart_candidates(F, face_part, val, labels, c, cost, unary, nb, colour, penalty, lams):
    """Candidate labelings that change invalid chart ``c``: merges into each neighbouring label;
    for each label of another axis missing around the chart, the faces of the chart and its
    neighbouring charts that fit that label better than their own take it; growing the chart
    over the faces of its part around its corners (so it gains a boundary with every chart that
    only touched it at a corner) and over its one-ring; local re-segmentations of the chart and
    its neighbours at coarser ``lam``.

    Returns
    -------
    list of Trial
    """
    lay = val.layout
    nbrs = same_part_neighbours(lay, c)
    in_c = lay.face_chart == c
    out = [Trial(f"merge_into_{lab}", cand) for lab, cand in neighbour_merges(lay, labels, c)]
    region = in_c | np.isin(lay.face_chart, nbrs)
    a = int(lay.chart_label[c])
    present = set(lay.chart_label[nbrs].tolist())
    cur_cost = cost[np.arange(len(labels)), labels]
    for lab in range(6):
        if lab // 2 == a // 2 or lab in present:
            continue
        grow = region & (cost[:, lab] < cur_cost)
        if grow.any():
            cand = labels.copy()
            cand[grow] = lab
            out.append(Trial(f"grow_missing_{lab}", cand))
    own_part = face_part == lay.chart_part[c]
    ring = np.zeros(len(lay.vertex_sep_degree), dtype=bool)
    ring[F[in_c]] = True
    at_corner = ring & (lay.vertex_sep_degree >= 3)
    for name, vmask in (("grow_at_corners", at_corner), ("grow_ring", ring)):
        grow = faces_at_vertices(F, vmask) & own_part & ~in_c
        if grow.any():
            cand = labels.copy()
            cand[grow] = a
            out.append(Trial(name, cand))
    for lam in lams:
        out.append(Trial(f"resegment_lambda_{lam:g}",
                         local_resegment(labels, unary, nb, colour, region, lam, penalty)))
    return out


def corner_growths(F, face_part, lay, labels, c):
    """Candidates that grow invalid chart ``c`` over the faces of its part around one of its
    corners at a time (one labeling per corner vertex of the chart): a chart that touches a
    neighbour only at that corner gains a boundary with it there, without the changes at its
    other corners that :func:`chart_candidates`' growth at all corners makes at once.

    Parameters
    ----------
    F : (m, 3) int64; face_part : (m,) int64; lay : ChartLayout of ``labels``;
    labels : (m,) int64; c : int, the chart.

    Returns
    -------
    list of Trial
    """
    in_c = lay.face_chart == c
    own = (face_part == lay.chart_part[c]) & ~in_c
    ring = np.zeros(len(lay.vertex_sep_degree), dtype=bool)
    ring[F[in_c]] = True
    out = []
    for v in np.flatnonzero(ring & (lay.vertex_sep_degree >= 3)).tolist():
        grow = own & (F == v).any(axis=1)
        if grow.any():
            cand = labels.copy()
            cand[grow] = lay.chart_label[c]
            out.append(Trial(f"grow_at_corner_{v}", cand))
    return out


def joint_merges(lay, labels, c, small):
    """Candidates that merge chart ``c`` together with its small neighbouring charts of its
    part (``small``: (c,) bool, the charts counted small) into each label around that group:
    where a small chart of the opposite label sits between ``c`` and a large neighbour, merging
    either alone leaves an opposite-label boundary (the repair tries them for an invalid chart
    when no candidate of :func:`chart_candidates` helps; the chart absorption for a small
    chart that no merge of its own can take).

    Returns
    -------
    list of Trial
    """
    part = lay.chart_part[c]
    nbrs = same_part_neighbours(lay, c)
    small = nbrs[small[nbrs]]
    if not len(small):
        return []
    group = np.concatenate([[c], small])
    around = np.unique(np.concatenate([lay.chart_neighbours[g].indices for g in group]))
    around = around[(lay.chart_part[around] == part) & ~np.isin(around, group)]
    in_group = np.isin(lay.face_chart, group)
    out = []
    for lab in np.unique(lay.chart_label[np.concatenate([around, [c]])]).tolist():
        cand = labels.copy()
        cand[in_group] = lab
        out.append(Trial(f"merge_with_small_into_{lab}", cand))
    return out

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Monotonicity pass: remove the turning points of a labeling without losing validity (after repair).

A turning point (:func:`core.segmentation.validity.check_validity`) is a vertex where a boundary
between charts of labels ``a`` and ``b`` reverses along its axis ``k`` (the axis perpendicular to
both); polycube deformations fold there, and the base mesh cannot make a rectilinear polygon of a
chart whose boundary turns. Two operators make candidates for every turning point (the
validity-first labeling work runs such a pass after validity):

- *hook move* (turning points at most :data:`MAX_HOOK` edges from an end of their boundary): the
  boundary leaves a corner backwards for a few edges because the corner sits a little off where
  the two charts really part. The *hook segment* is the chain from its nearer end to one vertex past
  the turning point; the faces of one of the two charts that touch the segment take the other
  chart's label (both sides are candidates), so the boundary leaves the corner along the far side
  of that strip.
- *turn chart*: where a boundary wraps around the end of a member (e.g. a +Y chart around three
  sides of a -Z chart) the polycube needs a chart of the third axis there. The faces of the part
  within ``r`` mean edge lengths of the turning point (``r`` in :data:`TURN_RADII`) whose normal
  cost for the label ``+k`` (or ``-k``) is at most :data:`TURN_SLACK` above that of their own
  label, connected to the faces at the turning point, take that label: the turn becomes two
  corners of a new chart.

Candidates are ranked by the Eq. 3 energy they add (``sum ||n - c_l||^2 + lambda *`` the change of
the number of edges between different labels) and judged in that order on the submesh around them
(exact: :meth:`core.segmentation.repair.CandidateJudge.delta_with_turning`); the first one that
removes turning points without adding invalid charts, boundaries or corners and keeps the
area-weighted mean normal-to-label angle within ``max_angle_increase`` of the input is applied.
Turning points whose judging zones overlap a change of the same round wait for the next round, which
starts from a fresh whole-mesh judgement.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from core.segmentation.charts import boundary_chains, build_topology
from core.segmentation.labeling import LAMBDA
from core.segmentation.repair import CandidateJudge
from core.segmentation.validity import sub_topology

MAX_HOOK = 10
"""Longest hook (edges from the nearer end of the boundary to the turning point) that is moved."""
NOTCH_RINGS = (1, 2)
"""Face rings around a turning point that the notch candidates move."""
TURN_CUT_LENGTH = 20.0
"""Longest turn-cut path, in mean edge lengths."""


def hook_move(F, cost, lay, chain, b, v, max_hook=MAX_HOOK):
    """Hook-move candidates at turning point ``v`` of boundary ``b`` (module docstring).

    Parameters
    ----------
    F : (m, 3) int64 faces; cost : (m, 6) float64 ``||n - c_l||^2``.
    lay : ChartLayout; chain : (vertices, edges, closed) of boundary ``b``.
    v : int, the turning point; max_hook : int.

    Returns
    -------
    list of (faces (k,) int64, new label int), one per side of the boundary, empty when the turning
    point is farther than ``max_hook`` edges from both ends or the charts lie in different parts.
    """
    verts = chain[0]
    i = int(np.flatnonzero(verts == v)[0])
    last = len(verts) - 1
    x, y = lay.boundary_charts[b]
    if min(i, last - i) > max_hook or lay.chart_part[x] != lay.chart_part[y]:
        return []
    seg = verts[:i + 2] if i <= last - i else verts[max(i - 1, 0):]
    on = np.zeros(lay.vertex_sep_degree.shape[0], dtype=bool)
    on[seg] = True
    touch = on[F].any(axis=1)
    out = []
    for p, q in ((x, y), (y, x)):
        faces = np.flatnonzero(touch & (lay.face_chart == p))
        if 0 < len(faces) < lay.chart_size[p]:
            out.append((faces, int(lay.chart_label[q])))
    return out


def turn_cut_moves(V, F, topology, lay, edge_chart, cost, edge_length, b, v, axis, tau,
                   max_length=TURN_CUT_LENGTH):
    """Turn-cut candidates at turning point ``v`` of boundary ``b`` (module docstring).

    For each chart ``x`` of the boundary: the shortest path (Dijkstra on the edges of ``x``'s
    faces, at most ``max_length * tau`` long) from ``v`` to a vertex where ``x`` meets a third
    chart; the faces of ``x`` touching the path take the label ``+k`` or ``-k`` of the boundary's
    axis ``k`` (the one of smaller normal cost), a strip that ends the boundary at ``v``.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; topology : MeshTopology; lay : ChartLayout.
    edge_chart : (e, 2) int64 chart of the two faces of every edge (``-1`` where none).
    cost : (m, 6) float64.
    edge_length : (e,) float64 length of every edge of ``topology``.
    b, v, axis : int, boundary, turning point and the boundary's axis; tau : float.
    max_length : float, longest path in ``tau``.

    Returns
    -------
    list of (faces (k,) int64, new label int).
    """
    pair = lay.boundary_charts[b]
    n = topology.n_vertices
    # only edges within reach of v (both ends closer than the longest path)
    near_v = np.linalg.norm(V - V[v], axis=1) <= max_length * tau
    near = np.flatnonzero(near_v[topology.edges[:, 0]] & near_v[topology.edges[:, 1]])
    # the search graph on the vertices within reach, numbered compactly
    gv, gev = np.unique(topology.edges[near], return_inverse=True)
    gev = gev.reshape(-1, 2)
    g_n = len(gv)
    src = int(np.searchsorted(gv, v))
    fc = edge_chart[near]
    out = []
    for x, y in (pair.tolist(), pair[::-1].tolist()):
        inx = (fc == x).any(axis=1)
        other = np.where(fc[:, 0] == x, fc[:, 1], fc[:, 0])
        third = inx & (other >= 0) & (other != x) & (other != y)
        # the path runs through x (not along its boundary with y) to where x meets a third chart
        inx &= other != y
        target = np.zeros(g_n, dtype=bool)
        target[gev[third].reshape(-1)] = True
        target[src] = False
        if not target.any():
            continue
        ev = gev[inx]
        g = sp.csr_matrix((edge_length[near[inx]], (ev[:, 0], ev[:, 1])), shape=(g_n, g_n))
        dist, pred = dijkstra(g, directed=False, indices=src, return_predecessors=True,
                              limit=max_length * tau)
        reach = np.flatnonzero(target & np.isfinite(dist))
        if not len(reach):
            continue
        t = int(reach[np.argmin(dist[reach])])
        path = [t]
        while path[-1] != src:
            path.append(int(pred[path[-1]]))
        on = np.zeros(n, dtype=bool)
        on[gv[path]] = True
        fx = np.flatnonzero(lay.face_chart == x)
        faces = fx[on[F[fx]].any(axis=1)]
        if not len(faces) or len(faces) >= lay.chart_size[x]:
            continue
        plus = cost[faces, 2 * axis].sum() <= cost[faces, 2 * axis + 1].sum()
        out.append((faces, 2 * axis if plus else 2 * axis + 1))
    return out


def notch_moves(F, lay, pair, around, rings=NOTCH_RINGS):
    """Notch candidates at a turning point: the faces of one of the boundary's two charts within
    ``r`` face rings of the turning point (``r`` in ``rings``; ``around`` are the faces at it) take
    the other chart's label, which straightens a boundary that zig-zags by a few edges.

    Returns
    -------
    list of (faces (k,) int64, new label int).
    """
    n = lay.vertex_sep_degree.shape[0]
    ring = np.zeros(len(F), dtype=bool)
    ring[around] = True
    out = []
    for r in range(1, max(rings) + 1):
        if r > 1:
            vm = np.zeros(n, dtype=bool)
            vm[F[ring]] = True
            ring = vm[F].any(axis=1)
        if r not in rings:
            continue
        for x, y in (pair.tolist(), pair[::-1].tolist()):
            faces = np.flatnonzero(ring & (lay.face_chart == x))
            if 0 < len(faces) < lay.chart_size[x]:
                out.append((faces, int(lay.chart_label[y])))
    return out


def _energy_increase(topology, labels, faces, new, cost, lam):
    """Eq. 3 energy added by giving ``faces`` the label ``new``: normal cost plus ``lam`` times the
    change in the number of edges between different labels (edges of the moved faces)."""
    cand_lab = labels[faces]
    unary = float((cost[faces, new] - cost[faces, cand_lab]).sum())
    edges = np.unique(topology.face_edges[faces])
    ef = topology.edge_faces[edges]
    ok = (ef >= 0).all(axis=1)
    ef = ef[ok]
    before = (labels[ef[:, 0]] != labels[ef[:, 1]]).sum()
    after_lab = labels.copy()
    after_lab[faces] = new
    after = (after_lab[ef[:, 0]] != after_lab[ef[:, 1]]).sum()
    return unary + lam * float(after - before)


def _vertex_faces(F, n_vertices):
    """CSR-style (indptr (n+1,), faces) of the faces around each vertex."""
    flat = F.reshape(-1)
    order = np.argsort(flat, kind="stable")
    indptr = np.searchsorted(flat[order], np.arange(n_vertices + 1))
    return indptr, order // 3


def straighten_boundaries(V, F, face_part, face_label, face_frame, topology=None,
                          edge_interface_axis=None, max_rounds=6, max_evaluations=None,
                          max_visits=None,
                          max_angle_increase=1.0, lam=LAMBDA, judge=None):
    """Remove turning points by hook moves and turn charts without losing validity (module docstring).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; face_part, face_label : (m,) int.
    face_frame : (m, 3, 3) float64 per-face frames.
    topology : MeshTopology, optional.
    edge_interface_axis : (e, 3) float64, optional (:func:`edge_interface_axes`).
    max_rounds : int, rounds (each ends with one whole-mesh judgement).
    max_evaluations : int, cap on candidate judgements per turning point and round (default 8 on
        meshes of at most 50000 faces, 1 above: each judgement walks the charts around the
        candidate).
    max_visits : int, cap on turning points visited (candidates made and judged) over the pass
        (default ``max(16, 2400000 // m)``: the work per visit grows with the charts around it).
    max_angle_increase : float, degrees.
    lam : float, Eq. 3 lambda used to rank candidates.
    judge : CandidateJudge, optional, of this mesh, parts and frames (the repair's, whose last
        judgements it keeps; built when omitted).

    Returns
    -------
    labels : (m,) int32.
    report : dict with ``turning_points_before``, ``turning_points_after``, ``moves`` (accepted, by
        operator), ``evaluations``, ``visits``, ``rounds`` and ``angle_before`` / ``angle_after``
        (area-weighted mean degrees).
    validity : Validity of the returned labels (turning points included), so callers need not
        judge them again.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    face_part = np.asarray(face_part, dtype=np.int64)
    labels = np.asarray(face_label, dtype=np.int64).copy()
    if topology is None:
        topology = build_topology(F, len(V))
    if max_evaluations is None:
        max_evaluations = 8 if m <= 50000 else 1
    if max_visits is None:
        max_visits = max(16, 2400000 // max(m, 1))
    if judge is None:
        judge = CandidateJudge.of_mesh(V, F, face_part, face_frame, topology,
                                       edge_ix=edge_interface_axis)
    cost, ang = judge.cost, judge.weighted_angle
    edge_length = np.linalg.norm(V[topology.edges[:, 0]] - V[topology.edges[:, 1]], axis=1)
    tau = float(edge_length.mean())
    vf_ptr, vf = _vertex_faces(F, topology.n_vertices)

    def judge_whole(lab):
        return judge.validity(lab, tau)

    val = judge_whole(labels)
    tp0 = len(val.turning_points)
    angle0 = float(ang[np.arange(m), labels].sum())
    angle_now = angle0
    cap = angle0 + max_angle_increase
    moves = {"notch": 0, "hook": 0, "turn_cut": 0}
    evaluations = 0
    visits = 0
    rounds = 0
    tried = set()
    strict = False
    for rounds in range(1, int(max_rounds) + 1):
        if not len(val.turning_points):
            rounds -= 1
            break
        lay = val.layout
        chains = boundary_chains(topology, lay, np.isin(np.arange(lay.n_boundaries),
                                                        val.turning_points[:, 0]))
        ef = topology.edge_faces
        edge_chart = np.where(ef >= 0, lay.face_chart[np.maximum(ef, 0)], -1)
        dirty = np.zeros(m, dtype=bool)
        accepted = 0
        start = (labels, angle_now, dict(moves), set(tried), visits)
        for b, v in val.turning_points.tolist():
            # tried again once either chart has changed
            pair = lay.boundary_charts[b]
            key = (int(v),) + tuple(lay.chart_label[pair].tolist() + lay.chart_size[pair].tolist())
            if key in tried:
                continue
            around = vf[vf_ptr[v]:vf_ptr[v + 1]]
            if dirty[around].any() or visits >= max_visits:
                continue
            tried.add(key)
            visits += 1
            cands = [("hook", f, n) for f, n in hook_move(F, cost, lay, chains[b], b, v)]
            if val.boundary_axis[b] >= 0:
                k = int(val.boundary_axis[b])
                cands += [("turn_cut", f, n) for f, n in turn_cut_moves(
                    V, F, topology, lay, edge_chart, cost, edge_length, b, v, k, tau)]
            cands += [("notch", f, n) for f, n in notch_moves(F, lay, pair, around)]
            scored = []
            for op, faces, new in cands:
                d_angle = float((ang[faces, new] - ang[faces, labels[faces]]).sum())
                if angle_now + d_angle > cap or dirty[faces].any():
                    continue
                scored.append((_energy_increase(topology, labels, faces, new, cost, lam),
                               len(scored), op, faces, new, d_angle))
            scored = sorted(scored, key=lambda t: (t[0], t[1]))[:int(max_evaluations)]
            if not scored:
                continue
            # one zone for all candidates of this turning point: the current labels are judged once
            vmask = np.zeros(topology.n_vertices, dtype=bool)
            for t in scored:
                vmask[F[t[3]]] = True
            zone = judge.zone_of(lay, vmask)
            if strict and dirty[zone].any():
                continue
            sub = sub_topology(topology, zone)
            if np.array_equal(labels[zone], start[0][zone]):  # the zone as val judged it
                inv0, tp_0 = judge.near(val, vmask)
            else:
                inv0, tp_0 = judge.local(labels, zone, vmask, tau, sub)
            for _e, _i, op, faces, new, d_angle in scored:
                cand = labels.copy()
                cand[faces] = new
                inv1, tp_1 = judge.local(cand, zone, vmask, tau, sub, max_invalid=inv0)
                evaluations += 1
                if inv1 <= inv0 and tp_1 < tp_0:
                    labels = cand
                    angle_now += d_angle
                    if strict:
                        dirty[zone] = True
                    else:
                        near = np.zeros(topology.n_vertices, dtype=bool)
                        near[F[faces]] = True
                        dirty |= near[F].any(axis=1)
                    moves[op] += 1
                    accepted += 1
                    break
        if not accepted:
            break
        new_val = judge_whole(labels)
        if not strict and (new_val.n_invalid > val.n_invalid
                           or len(new_val.turning_points) >= len(val.turning_points)):
            # moves judged against a layout that earlier moves of the round had changed did
            # not add up: redo the round with disjoint judging zones
            labels, angle_now, moves, tried, visits = start
            strict = True
            continue
        val = new_val
    report = {"turning_points_before": int(tp0), "turning_points_after": len(val.turning_points),
              "moves": moves, "evaluations": int(evaluations), "visits": int(visits),
              "rounds": int(rounds),
              "angle_before": angle0, "angle_after": float(ang[np.arange(m), labels].sum())}
    return labels.astype(np.int32), report, val

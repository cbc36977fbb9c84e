# SPDX-License-Identifier: LGPL-2.1-or-later
"""Monotonicity pass: remove the turning points of a labeling without losing validity (after repair).

A turning point (:func:`core.segmentation.validity.check_validity`) is a vertex where a boundary
between charts of labels ``a`` and ``b`` reverses along its axis ``k`` (the axis perpendicular to
both); polycube deformations fold there, and the base mesh cannot make a rectilinear polygon of a
chart whose boundary turns. Three operators make candidates for every turning point (the
validity-first labeling work runs such a pass after validity):

- *hook move* (turning points at most :data:`MAX_HOOK` edges from an end of their boundary): the
  boundary leaves a corner backwards for a few edges because the corner sits a little off where
  the two charts really part. The *hook segment* is the chain from its nearer end to one vertex past
  the turning point; the faces of one of the two charts that touch the segment take the other
  chart's label (both sides are candidates), so the boundary leaves the corner along the far side
  of that strip.
- *turn cut*: where a boundary wraps around the end of a member (e.g. a +Y chart around three
  sides of a -Z chart) the polycube needs a chart of the third axis there. The faces of one of the
  two charts along the shortest path (at most :data:`TURN_CUT_LENGTH` mean edge lengths) from the
  turning point to where that chart meets a third chart take the label ``+k`` or ``-k`` of the
  boundary's axis: the turn becomes two corners of a new strip chart (:func:`turn_cut_moves`).

A third operator, the *notch*, gives the faces of one chart within one or two face rings of the
turning point the other chart's label (a boundary that zig-zags by a few edges).

Candidates are ranked by the Eq. 3 energy they add (``sum ||n - c_l||^2 + lambda *`` the change of
the number of edges between different labels). The pass runs in rounds: each proposes every
turning point's next candidate in that order, applies those far enough apart together and judges
the whole mesh once (:func:`straighten_boundaries`); a candidate counts when its neighbourhood lost
turning points and gained no invalid chart, boundary or corner, and the area-weighted mean
normal-to-label angle stays within ``max_angle_increase`` of the input. Judging candidates one by
one on the charts around them would cost, on a fine mesh, as much per candidate as a whole-mesh
judgement (the charts are most of the mesh), so the pass would run out of its budget long before
it reached every turning point.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from core.mesh_topology import vertex_face_matrix
from core.segmentation.charts import boundary_chains, build_topology
from core.segmentation.labeling import LAMBDA
from core.segmentation.repair import CandidateJudge
from core.segmentation.validity import boundaries_at

MAX_HOOK = 10
"""Longest hook (edges from the nearer end of the boundary to the turning point) that is moved."""
NOTCH_RINGS = (1, 2)
"""Face rings around a turning point that the notch candidates move."""
TURN_CUT_LENGTH = 20.0
"""Longest turn-cut path, in mean edge lengths."""


def hook_move(F, cost, lay, chain, b, v, max_hook=MAX_HOOK, vertex_faces=None):
    """Hook-move candidates at turning point ``v`` of boundary ``b`` (module docstring).

    Parameters
    ----------
    F : (m, 3) int64 faces; cost : (m, 6) float64 ``||n - c_l||^2``.
    lay : ChartLayout; chain : (vertices, edges, closed) of boundary ``b``.
    v : int, the turning point; max_hook : int.
    vertex_faces : optional :func:`_vertex_faces` of ``F`` (computed when omitted).

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
    if vertex_faces is None:
        vertex_faces = _vertex_faces(F, lay.vertex_sep_degree.shape[0])
    touch = faces_at(vertex_faces, seg)
    out = []
    for p, q in ((x, y), (y, x)):
        faces = touch[lay.face_chart[touch] == p]
        if 0 < len(faces) < lay.chart_size[p]:
            out.append((faces, int(lay.chart_label[q])))
    return out


def turn_cut_moves(V, F, topology, lay, edge_chart, cost, edge_length, b, v, axis, tau,
                   max_length=TURN_CUT_LENGTH, vertex_faces=None, tree=None):
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
    vertex_faces : optional :func:`_vertex_faces` of ``F`` (computed when omitted).
    tree : optional ``scipy.spatial.cKDTree`` of ``V`` (built when omitted), to find the vertices
        within reach without a pass over the mesh.

    Returns
    -------
    list of (faces (k,) int64, new label int).
    """
    pair = lay.boundary_charts[b]
    if vertex_faces is None:
        vertex_faces = _vertex_faces(F, topology.n_vertices)
    if tree is None:
        tree = cKDTree(V)
    # only edges within reach of v (both ends closer than the longest path)
    ball = np.asarray(tree.query_ball_point(V[v], max_length * tau), dtype=np.int64)
    near_v = np.zeros(len(V), dtype=bool)
    near_v[ball] = True
    near = np.unique(topology.face_edges[faces_at(vertex_faces, ball)])
    near = near[near_v[topology.edges[near, 0]] & near_v[topology.edges[near, 1]]]
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
        faces = faces_at(vertex_faces, gv[path])
        faces = faces[lay.face_chart[faces] == x]
        if not len(faces) or len(faces) >= lay.chart_size[x]:
            continue
        plus = cost[faces, 2 * axis].sum() <= cost[faces, 2 * axis + 1].sum()
        out.append((faces, 2 * axis if plus else 2 * axis + 1))
    return out


def notch_moves(F, lay, pair, around, rings=NOTCH_RINGS, vertex_faces=None):
    """Notch candidates at a turning point: the faces of one of the boundary's two charts within
    ``r`` face rings of the turning point (``r`` in ``rings``; ``around`` are the faces at it) take
    the other chart's label, which straightens a boundary that zig-zags by a few edges.
    ``vertex_faces`` : optional :func:`_vertex_faces` of ``F`` (computed when omitted).

    Returns
    -------
    list of (faces (k,) int64, new label int).
    """
    if vertex_faces is None:
        vertex_faces = _vertex_faces(F, lay.vertex_sep_degree.shape[0])
    ring = np.unique(np.asarray(around, dtype=np.int64))
    out = []
    for r in range(1, max(rings) + 1):
        if r > 1:
            ring = faces_at(vertex_faces, np.unique(F[ring]))
        if r not in rings:
            continue
        for x, y in (pair.tolist(), pair[::-1].tolist()):
            faces = ring[lay.face_chart[ring] == x]
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
    ef = ef[(ef >= 0).all(axis=1)]
    old = labels[ef]
    after = np.where(np.isin(ef, faces), new, old)
    before = (old[:, 0] != old[:, 1]).sum()
    return unary + lam * float((after[:, 0] != after[:, 1]).sum() - before)


def _vertex_faces(F, n_vertices):
    """(n, m) CSR vertex-face incidence (:func:`core.mesh_topology.vertex_face_matrix`): row ``v``
    lists the faces around vertex ``v``."""
    return vertex_face_matrix(F, n_vertices)


def faces_at(vertex_faces, verts):
    """(k,) int64 sorted faces with a vertex in ``verts``, from the CSR ``vertex_faces``
    (:func:`_vertex_faces`): the work grows with the faces found, not with the mesh."""
    ptr, vf = vertex_faces.indptr, vertex_faces.indices
    verts = np.asarray(verts, dtype=np.int64).reshape(-1)
    start, count = ptr[verts], ptr[verts + 1] - ptr[verts]
    first = np.cumsum(count) - count
    idx = np.repeat(start - first, count) + np.arange(int(count.sum()))
    return np.unique(vf[idx]).astype(np.int64)


def straighten_boundaries(V, F, face_part, face_label, face_frame, topology=None,
                          edge_interface_axis=None, max_rounds=12, max_evaluations=8,
                          max_visits=None, max_angle_increase=1.0, lam=LAMBDA, judge=None):
    """Remove turning points by notches, hook moves and turn cuts without losing validity (module
    docstring).

    Each round proposes, for every turning point, its next untried candidate (cheapest Eq. 3
    energy first, within the angle budget): proposals whose faces share no vertex and whose
    changed vertices touch no common boundary are applied together and the whole mesh is judged
    once. A proposal is kept when the items near it (:meth:`CandidateJudge.near`: charts,
    boundaries and corners touching its vertices, turning points on the boundaries through them)
    lost turning points and gained no invalid item; the kept ones are judged together again and
    taken when the whole mesh has no more invalid items and fewer turning points, otherwise one
    at a time, each judged on the whole mesh. On a fine mesh the charts around a candidate are
    large, so a whole-mesh judgement costs about what judging one candidate on its charts does,
    and a round costs two of them however many turning points it treats.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; face_part, face_label : (m,) int.
    face_frame : (m, 3, 3) float64 per-face frames.
    topology : MeshTopology, optional.
    edge_interface_axis : (e, 3) float64, optional (:func:`edge_interface_axes`).
    max_rounds : int, rounds (each judges the whole mesh once or twice, more only when kept
        proposals have to be taken one at a time).
    max_evaluations : int, cap on the candidates proposed per turning point (keyed by its vertex
        and the labels of its boundary) over the pass.
    max_visits : int, cap on the whole-mesh judgements over the pass: no round starts once it is
        reached (default ``max(8, 1200000 // m)``, each costs a pass over the charts).
    max_angle_increase : float, degrees.
    lam : float, Eq. 3 lambda used to rank candidates.
    judge : CandidateJudge, optional, of this mesh, parts and frames (the repair's, whose last
        judgements it keeps; built when omitted).

    Returns
    -------
    labels : (m,) int32.
    report : dict with ``turning_points_before``, ``turning_points_after``, ``moves`` (accepted, by
        operator), ``evaluations`` (proposals judged), ``visits`` (whole-mesh judgements),
        ``rounds`` and ``angle_before`` / ``angle_after`` (area-weighted mean degrees).
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
    if max_visits is None:
        max_visits = max(8, 1200000 // max(m, 1))
    if judge is None:
        judge = CandidateJudge.of_mesh(V, F, face_part, face_frame, topology,
                                       edge_ix=edge_interface_axis)
    cost, ang = judge.cost, judge.weighted_angle
    edge_length = np.linalg.norm(V[topology.edges[:, 0]] - V[topology.edges[:, 1]], axis=1)
    tau = float(edge_length.mean())
    vfm = _vertex_faces(F, topology.n_vertices)
    tree = cKDTree(V)
    judged = [0]

    def judge_whole(lab):
        judged[0] += 1
        return judge.validity(lab, tau)

    def better(new, old):
        return (new.n_invalid <= old.n_invalid
                and len(new.turning_points) < len(old.turning_points))

    val = judge_whole(labels)
    tp0 = len(val.turning_points)
    angle0 = float(ang[np.arange(m), labels].sum())
    angle_now = angle0
    cap = angle0 + max_angle_increase
    moves = {"notch": 0, "hook": 0, "turn_cut": 0}
    evaluations = 0
    rounds = 0
    tries = {}
    for rounds in range(1, int(max_rounds) + 1):
        if not len(val.turning_points) or judged[0] >= max_visits:
            rounds -= 1
            break
        proposals = _propose(V, F, topology, val, labels, cost, ang, edge_length, tau,
                             (vfm, tree), tries, cap - angle_now, lam, max_evaluations)
        if not proposals:
            rounds -= 1
            break
        evaluations += len(proposals)
        trial = _apply(labels, proposals)
        new_val = judge_whole(trial)
        keep = []
        for prop in proposals:
            inv0, tp_0 = judge.near(val, prop[4])
            inv1, tp_1 = judge.near(new_val, prop[4])
            if inv1 <= inv0 and tp_1 < tp_0:
                keep.append(prop)
        if keep and len(keep) < len(proposals):
            trial = _apply(labels, keep)
            new_val = judge_whole(trial)
        if keep and better(new_val, val):
            taken = keep
            labels, val = trial, new_val
        else:
            taken = []
            for prop in keep:
                cand = _apply(labels, [prop])
                single = judge_whole(cand)
                if better(single, val):
                    labels, val = cand, single
                    taken.append(prop)
        for op, _faces, _new, d_angle, _vm in taken:
            moves[op] += 1
            angle_now += d_angle
    report = {"turning_points_before": int(tp0), "turning_points_after": len(val.turning_points),
              "moves": moves, "evaluations": int(evaluations), "visits": int(judged[0]),
              "rounds": int(rounds),
              "angle_before": angle0, "angle_after": float(ang[np.arange(m), labels].sum())}
    return labels.astype(np.int32), report, val


def _apply(labels, proposals):
    """Copy of ``labels`` with every proposal ``(op, faces, new, ...)`` applied."""
    out = labels.copy()
    for prop in proposals:
        out[prop[1]] = prop[2]
    return out


def _propose(V, F, topology, val, labels, cost, ang, edge_length, tau, lookup, tries, budget,
             lam, max_evaluations):
    """One round's proposals of :func:`straighten_boundaries`: per turning point of ``val`` its
    next untried candidate (``tries`` counts them per key, updated in place), skipping turning
    points next to an earlier proposal of the round. ``lookup`` is (:func:`_vertex_faces` of
    ``F``, ``cKDTree`` of ``V``).

    Returns
    -------
    list of (op str, faces (k,) int64, new label int, angle change float, changed vertices (n,)
    bool).
    """
    m = len(F)
    vfm, tree = lookup
    lay = val.layout
    chains = boundary_chains(topology, lay, np.isin(np.arange(lay.n_boundaries),
                                                    val.turning_points[:, 0]))
    ef = topology.edge_faces
    edge_chart = np.where(ef >= 0, lay.face_chart[np.maximum(ef, 0)], -1)
    dirty = np.zeros(m, dtype=bool)
    touched = np.zeros(lay.n_boundaries, dtype=bool)
    out = []
    for b, v in val.turning_points.tolist():
        around = vfm.indices[vfm.indptr[v]:vfm.indptr[v + 1]]
        if touched[b] or dirty[around].any():
            continue
        pair = lay.boundary_charts[b]
        key = (int(v),) + tuple(sorted(lay.chart_label[pair].tolist()))
        done = tries.get(key, 0)
        if done >= max_evaluations:
            continue
        cands = [("hook", f, n) for f, n in hook_move(F, cost, lay, chains[b], b, v,
                                                      vertex_faces=vfm)]
        if val.boundary_axis[b] >= 0:
            k = int(val.boundary_axis[b])
            cands += [("turn_cut", f, n) for f, n in turn_cut_moves(
                V, F, topology, lay, edge_chart, cost, edge_length, b, v, k, tau,
                vertex_faces=vfm, tree=tree)]
        cands += [("notch", f, n) for f, n in notch_moves(F, lay, pair, around,
                                                          vertex_faces=vfm)]
        scored = []
        for op, faces, new in cands:
            d_angle = float((ang[faces, new] - ang[faces, labels[faces]]).sum())
            if d_angle > budget or dirty[faces].any():
                continue
            scored.append((_energy_increase(topology, labels, faces, new, cost, lam),
                           len(scored), op, faces, new, d_angle))
        scored.sort(key=lambda t: (t[0], t[1]))
        if done >= len(scored):
            tries[key] = max_evaluations
            continue
        _e, _i, op, faces, new, d_angle = scored[done]
        vmask = np.zeros(topology.n_vertices, dtype=bool)
        vmask[F[faces]] = True
        bnd = boundaries_at(topology, lay, vmask)
        if (bnd & touched).any():
            continue
        tries[key] = done + 1
        touched |= bnd
        dirty[faces_at(vfm, np.unique(F[faces]))] = True
        budget -= d_angle
        out.append((op, faces, new, d_angle, vmask))
    return out

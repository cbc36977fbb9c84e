# SPDX-License-Identifier: LGPL-2.1-or-later
"""Monotonicity pass: straighten boundary hooks that make turning points (run after repair).

A turning point (:func:`core.segmentation.validity.check_validity`) is a vertex where a boundary
reverses along its axis; polycube deformations fold there. Many of them are *hooks*: the
boundary leaves a corner backwards for a few edges and then runs on monotonically, because the
corner sits a little off where the two charts really part. The pass moves the hook: for a turning
point at position ``i`` of a boundary chain of ``L`` edges with ``min(i, L - i)`` at most
:data:`MAX_HOOK`, the *hook segment* is the chain from its nearer end to one vertex past the
turning point; the faces of one of the two charts that touch
the segment take the other chart's label (of the two sides, the one that costs less normal
deviation ``sum ||n - c_l||^2``), so the boundary now leaves the corner along the far side of that
strip.

Moves of different turning points whose faces share no vertex are applied together and judged
once on the whole mesh; a batch is kept when it has no more invalid charts, boundaries and corners
than before, fewer turning points, and keeps the area-weighted mean normal-to-label angle within
``max_angle_increase`` of the input. A rejected batch is split in halves and each half judged (down
to single moves, at most ``max_checks`` judgements in all). Turning points that are not hooks
(a boundary that wraps around the end of a member and comes back) are left: they need a new chart,
which this pass does not insert.
"""
import numpy as np

from core.geometry import face_areas
from core.segmentation.charts import boundary_chains, build_topology
from core.segmentation.labeling import face_normals, label_cost
from core.segmentation.validity import check_validity, edge_interface_axes

MAX_HOOK = 10
"""Longest hook (edges from the nearer end of the boundary to the turning point) that is moved."""


def hook_moves(F, labels, cost, topology, validity, tried, max_hook=MAX_HOOK):
    """Candidate moves, one per turning point not tried yet.

    Parameters
    ----------
    F : (m, 3) int64 faces; labels : (m,) int64.
    cost : (m, 6) float64 label cost ``||n - c_l||^2``.
    topology : MeshTopology; validity : Validity of ``labels`` with turning points.
    tried : set of (vertex, chart label) keys already tried; updated.
    max_hook : int, turning points farther than this many edges from both ends of their
        boundary are no hooks and get no move.

    Returns
    -------
    list of (faces (k,) int64, new label int) moves.
    """
    lay = validity.layout
    chains = boundary_chains(topology, lay)
    n = topology.n_vertices
    moves = []
    for b, v in validity.turning_points.tolist():
        verts = chains[b][0]
        i = int(np.flatnonzero(verts == v)[0])
        last = len(verts) - 1
        if min(i, last - i) > max_hook:
            continue
        seg = verts[:i + 2] if i <= last - i else verts[max(i - 1, 0):]
        on = np.zeros(n, dtype=bool)
        on[seg] = True
        touch = on[F].any(axis=1)
        best = None
        for x, y in (lay.boundary_charts[b], lay.boundary_charts[b][::-1]):
            key = (int(v), int(lay.chart_label[x]))
            if key in tried or lay.chart_part[x] != lay.chart_part[y]:
                continue
            faces = np.flatnonzero(touch & (lay.face_chart == x))
            if len(faces) == 0 or len(faces) >= lay.chart_size[x]:
                continue
            new = int(lay.chart_label[y])
            extra = float((cost[faces, new] - cost[faces, labels[faces]]).sum())
            if best is None or extra < best[0]:
                best = (extra, faces, new, key)
        if best is not None:
            tried.add(best[3])
            moves.append((best[1], best[2]))
    return moves


def _disjoint(F, moves, n_vertices):
    """Greedy subset of ``moves`` whose faces share no vertex, and the rest."""
    used = np.zeros(n_vertices, dtype=bool)
    keep, rest = [], []
    for mv in moves:
        vs = F[mv[0]].reshape(-1)
        if used[vs].any():
            rest.append(mv)
        else:
            used[vs] = True
            keep.append(mv)
    return keep, rest


def straighten_boundaries(V, F, face_part, face_label, face_frame, topology=None,
                          edge_interface_axis=None, max_rounds=4, max_checks=None,
                          max_angle_increase=0.5):
    """Move boundary hooks to remove turning points without losing validity (module docstring).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; face_part, face_label : (m,) int.
    face_frame : (m, 3, 3) float64 per-face frames.
    topology : MeshTopology, optional.
    edge_interface_axis : (e, 3) float64, optional (:func:`edge_interface_axes`).
    max_rounds : int, rounds of fresh candidates.
    max_checks : int, cap on whole-mesh judgements (default ``clip(500000 // m, 2, 24)``: each
        judgement walks every boundary, so big meshes get fewer).
    max_angle_increase : float, degrees.

    Returns
    -------
    labels : (m,) int32.
    report : dict with ``turning_points_before``, ``turning_points_after``, ``moves`` (accepted),
        ``checks`` and ``angle_before`` / ``angle_after`` (area-weighted mean degrees).
    validity : Validity of the returned labels (turning points included), so callers need not
        judge them again.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    labels = np.asarray(face_label, dtype=np.int64).copy()
    if topology is None:
        topology = build_topology(F, len(V))
    if max_checks is None:
        max_checks = int(np.clip(500000 // max(len(F), 1), 2, 24))
    if edge_interface_axis is None:
        edge_interface_axis = edge_interface_axes(V, topology, face_part)
    cost = label_cost(face_normals(V, F), face_frame)
    area = face_areas(V, F)
    weight = area / area.sum()
    rows = np.arange(len(F))

    def angle(lab):
        c = cost[rows, lab]
        return float(np.degrees(np.arccos(np.clip(1.0 - 0.5 * c, -1.0, 1.0))) @ weight)

    def judge(lab):
        return check_validity(V, F, face_part, lab, face_frame, topology,
                              edge_interface_axis=edge_interface_axis)

    val = judge(labels)
    tp0, angle0 = len(val.turning_points), angle(labels)
    cap = angle0 + max_angle_increase
    checks = 1
    accepted = 0
    tried = set()

    def better(v_new, lab):
        return (v_new.n_invalid <= val.n_invalid
                and len(v_new.turning_points) < len(val.turning_points) and angle(lab) <= cap)

    for _ in range(int(max_rounds)):
        moves = hook_moves(F, labels, cost, topology, val, tried)
        if not moves or checks >= max_checks:
            break
        batch, _rest = _disjoint(F, moves, topology.n_vertices)
        pending = [batch]
        progress = False
        while pending and checks < max_checks:
            group = pending.pop(0)
            cand = labels.copy()
            for faces, new in group:
                cand[faces] = new
            v_c = judge(cand)
            checks += 1
            if better(v_c, cand):
                labels, val = cand, v_c
                accepted += len(group)
                progress = True
            elif len(group) > 1:
                half = len(group) // 2
                pending[:0] = [group[:half], group[half:]]
        if not progress and not val.turning_points.size:
            break
    report = {"turning_points_before": int(tp0), "turning_points_after": len(val.turning_points),
              "moves": int(accepted), "checks": int(checks), "angle_before": angle0,
              "angle_after": angle(labels)}
    return labels.astype(np.int32), report, val

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Chart absorption: small and thin charts of a labeling taken into their neighbours.

Many charts of a labeling of an iso-surface are noise of the surface, not features of the
design: a patch of a third label where a strut meets a plate, a sliver along the edge between
two faces. Every chart becomes a rectilinear polygon of the quantized polycube with sides at
least one unit long, so such charts set the size of the smallest layout
(:mod:`core.quadmesh.polycube.quantize`) far above what the design needs. This pass removes
them before the base mesh is built, where the labeling stays as valid as it was.

A chart is a *candidate* when its area is below :data:`SMALL_AREA` quads of the face budget
(``unit_area`` = surface area / budget) or its width ``2 A / P`` (area over perimeter; half the
side of a square, the width of a long strip) is below :data:`THIN_WIDTH` quad edges
(``sqrt(unit_area)``). Each candidate gets these trials:

- *merge*: the whole chart takes the label of one neighbouring chart of its part (one trial per
  neighbouring label), so it joins that chart;
- *dissolve*: every face of the chart takes the label of the nearest neighbouring chart of its
  part (grown face by face from the chart's boundary, ties broken by the label cost
  ``||n - c_l||^2``), so a strip between two charts is split between them along its middle.

A trial is admissible when, judged exactly on the charts around it
(:meth:`core.segmentation.repair.CandidateJudge.local`), it adds no invalid chart, boundary or
corner, no turning point and no boundary loop without corners (which no polycube face can
have), the faces it changes fit their new label within :data:`MAX_MEAN_ANGLE` on average, and
the area-weighted mean angle between normals and label directions over the whole surface
stays within ``max_angle_increase`` degrees of the input's; of a chart's admissible
trials the one of least angle increase is taken. Charts are treated smallest first in rounds:
a round judges every candidate except those next to a chart it has already taken (no two taken
charts share a vertex with a common chart, so each local judgement holds with the others
applied), so a candidate no trial admits costs no round; one large chart around many small
ones would otherwise let a round take one of them only. The round's changes are judged together
on the whole mesh and kept when the whole labeling has no more invalid items and turning points
than before, else one at a time. A chart no trial admits is not tried again while it is
unchanged.
Validity-first repair merges invalid charts the same way (:mod:`core.segmentation.repair`); here
the charts are valid ones that are too small for the layout.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from core.errors import ParameterError
from core.geometry import face_areas
from core.segmentation.repair_operators import joint_merges, neighbour_merges
from core.segmentation.charts import OPPOSITE, extract_layout
from core.segmentation.validity import boundaries_at, sub_topology

SMALL_AREA = 1.0
"""Charts with less area than this many quads of the budget are candidates."""
THIN_WIDTH = 0.25
"""Charts narrower (``2 A / P``) than this many quad edges of the budget are candidates."""
MAX_MEAN_ANGLE = 75.0
"""Degrees: a trial whose changed faces would have a larger area-weighted mean angle between
their normals and their new label directions is not admissible (noise lies between the
directions of its neighbours; a wall of the design stands across them)."""


@dataclass(frozen=True)
class Absorption:
    """Result of :func:`absorb_charts`.

    labels : (m,) int64 labels 0..5 after the pass.
    validity : Validity of ``labels`` with turning points (hysteresis ``tau`` of the pass).
    report : dict (JSON-serialisable): ``charts_before``, ``charts_after``, ``absorbed``
        (charts taken, by trial kind), ``refused`` (candidates no trial admitted), ``rounds``,
        ``angle_before`` / ``angle_after`` (area-weighted mean degrees).
    """

    labels: np.ndarray
    validity: object
    report: dict


def chart_measures(V, topology, layout, area):
    """Area and width of every chart.

    Parameters
    ----------
    V : (n, 3) float64 vertices; topology : MeshTopology; layout : ChartLayout.
    area : (m,) float64 face areas.

    Returns
    -------
    chart_area : (c,) float64 (mesh units squared).
    chart_width : (c,) float64 ``2 A / P`` with ``P`` the length of the chart's separating
        edges (mesh units; ``inf`` for a chart without any, a whole closed component).
    """
    n = layout.n_charts
    chart_area = np.bincount(layout.face_chart, weights=area, minlength=n)
    ev = topology.edges[layout.sep_edges]
    length = np.linalg.norm(V[ev[:, 0]] - V[ev[:, 1]], axis=1)
    sides = layout.boundary_charts[layout.sep_boundary]
    perimeter = (np.bincount(sides[:, 0], weights=length, minlength=n)
                 + np.bincount(sides[:, 1], weights=length, minlength=n))
    with np.errstate(divide="ignore"):
        width = np.where(perimeter > 0, 2.0 * chart_area / np.maximum(perimeter, 1e-300), np.inf)
    return chart_area, width


def dissolved_labels(topology, face_part, labels, face_chart, chart, cost):
    """Labels with every face of ``chart`` given the label of its nearest neighbouring chart.

    Faces are reached breadth-first from the faces of the part outside the chart across the
    chart's edges; a face reached from several labels in one step takes the one of least
    ``cost``.

    Parameters
    ----------
    topology : MeshTopology; face_part, labels, face_chart : (m,) int64.
    chart : int; cost : (m, 6) float64 ``||n - c_l||^2``.

    Returns
    -------
    (m,) int64 labels (a copy), or None when the chart has no neighbour in its part.
    """
    faces = np.flatnonzero(face_chart == chart)
    nb = topology.neighbours[faces]
    new = labels.copy()
    done = np.ones(len(labels), dtype=bool)
    done[faces] = False
    same_part = (nb >= 0) & (face_part[np.maximum(nb, 0)] == face_part[faces][:, None])
    if not (same_part & (face_chart[np.maximum(nb, 0)] != chart)).any():
        return None
    todo = faces
    while len(todo):
        nb = topology.neighbours[todo]
        ok = (nb >= 0) & (face_part[np.maximum(nb, 0)] == face_part[todo][:, None])
        ok &= done[np.maximum(nb, 0)]
        reached = ok.any(axis=1)
        if not reached.any():
            break  # the rest touches only other parts: keeps its label
        offered = np.where(ok, new[np.maximum(nb, 0)], -1)
        rows = np.flatnonzero(reached)
        c = np.where(offered[rows] >= 0,
                     cost[todo[rows][:, None], np.maximum(offered[rows], 0)], np.inf)
        new[todo[rows]] = offered[rows, np.argmin(c, axis=1)]
        done[todo[rows]] = True
        todo = todo[~reached]
    return new


def _chart_vertex_adjacency(F, layout, n_vertices):
    """(c, c) CSR bool: charts that share a vertex (each chart with itself too)."""
    m = len(F)
    incidence = sp.csr_matrix((np.ones(3 * m, dtype=np.int32),
                               (np.repeat(layout.face_chart, 3), F.reshape(-1))),
                              shape=(layout.n_charts, n_vertices))
    incidence.data[:] = 1
    adj = (incidence @ incidence.T).tocsr()
    adj.data[:] = 1
    return adj


def _trials(topology, face_part, labels, layout, chart, cost, small):
    """(name, labels) trials for ``chart`` (module docstring); ``small``: (c,) bool candidate
    charts, for the group merges."""
    merges = neighbour_merges(layout, labels, chart)
    out = [("merge", cand) for _, cand in merges]
    if len(merges) > 1:
        cand = dissolved_labels(topology, face_part, labels, layout.face_chart, chart, cost)
        if cand is not None:
            out.append(("dissolve", cand))
    out += [("group", t.labels) for t in joint_merges(layout, labels, chart, small)]
    return out


def absorb_charts(V, F, face_part, face_label, judge, unit_area, max_rounds=40,
                  max_angle_increase=4.0, small_area=SMALL_AREA, thin_width=THIN_WIDTH,
                  tau=None):
    """Absorb the small and thin charts of a labeling into their neighbours (module docstring).

    Parameters
    ----------
    V : (n, 3) float64 vertices; F : (m, 3) int64 faces.
    face_part : (m,) int part of each face; face_label : (m,) int labels 0..5 (not modified).
    judge : core.segmentation.repair.CandidateJudge of this mesh, parts and frames.
    unit_area : float > 0, area of one quad of the face budget (mesh units squared): the
        surface area over the budget.
    max_rounds : int >= 0, rounds of absorptions (each takes charts that share no neighbour).
    max_angle_increase : float >= 0, degrees of area-weighted mean angle the pass may add.
    small_area, thin_width : float, candidates' area (quads) and width (quad edges) limits.
    tau : float, hysteresis of the turning points (mesh units; default the mean edge length,
        as :func:`core.segmentation.monotone.straighten_boundaries`).

    Returns
    -------
    Absorption
    """
    if not unit_area > 0:
        raise ParameterError(f"unit_area must be > 0, got {unit_area}")
    if int(max_rounds) < 0 or not max_angle_increase >= 0:
        raise ParameterError(f"max_rounds must be >= 0 and max_angle_increase >= 0, got "
                             f"{max_rounds}, {max_angle_increase}")
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    labels = np.asarray(face_label, dtype=np.int64).copy()
    m = len(F)
    topology = judge.topology
    if tau is None:
        tau = float(np.linalg.norm(V[topology.edges[:, 0]] - V[topology.edges[:, 1]],
                                   axis=1).mean())
    area = face_areas(V, F)
    ang, cost = judge.weighted_angle, judge.cost
    angle0 = float(ang[np.arange(m), labels].sum())
    val = judge.validity(labels, tau)
    charts_before = val.layout.n_charts
    absorbed = {"merge": 0, "dissolve": 0, "group": 0}
    refused = set()
    rounds = 0
    while rounds < int(max_rounds):
        lay = val.layout
        chart_area, width = chart_measures(V, topology, lay, area)
        small = ((chart_area < small_area * unit_area)
                 | (width < thin_width * np.sqrt(unit_area)))
        key = np.stack([lay.chart_first_face, lay.chart_label, lay.chart_size], axis=1).tolist()
        fresh = small & np.array([tuple(k) not in refused for k in key], dtype=bool)
        if not fresh.any():
            break
        rounds += 1
        cands = np.flatnonzero(fresh)
        order = cands[np.lexsort((cands, chart_area[cands]))]
        ring2 = _chart_vertex_adjacency(F, lay, topology.n_vertices)
        ring2 = (ring2 @ ring2).tocsr()
        blocked = np.zeros(lay.n_charts, dtype=bool)
        budget = angle0 + max_angle_increase - float(ang[np.arange(m), labels].sum())
        proposals = []
        for c in order.tolist():
            if blocked[c]:
                continue  # next to a chart taken this round: judged again on the next one
            best = _best_trial(judge, val, labels, _trials(topology, face_part, labels, lay, c,
                                                           cost, small), tau, budget)
            if best is None:
                refused.add(tuple(key[c]))
                continue
            blocked[ring2.indices[ring2.indptr[c]:ring2.indptr[c + 1]]] = True
            budget -= best[3]
            proposals.append(best + (tuple(key[c]),))
        if not proposals:
            continue
        trial = labels.copy()
        for _name, changed, cand, _d, _key in proposals:
            trial[changed] = cand[changed]
        whole = judge.validity(trial, tau)
        if _no_worse(topology, whole, val):
            labels, val = trial, whole
            for name, *_rest in proposals:
                absorbed[name] += 1
            continue
        for name, changed, cand, _d, chart_key in proposals:
            one = labels.copy()
            one[changed] = cand[changed]
            single = judge.validity(one, tau)
            if _no_worse(topology, single, val):
                labels, val = one, single
                absorbed[name] += 1
            else:
                refused.add(chart_key)
    report = {"charts_before": int(charts_before), "charts_after": int(val.layout.n_charts),
              "absorbed": absorbed, "refused": len(refused), "rounds": int(rounds),
              "angle_before": angle0, "angle_after": float(ang[np.arange(m), labels].sum())}
    return Absorption(labels, val, report)


def _best_trial(judge, val, labels, trials, tau, budget):
    """The admissible trial of least angle increase (module docstring), as ``(name, changed
    (m,) bool, labels, angle increase)``, or None.

    Parameters
    ----------
    judge : CandidateJudge; val : Validity of ``labels`` with turning points (``tau``).
    labels : (m,) int64 current labels; trials : list of (name, (m,) int64 labels).
    tau : float, turning-point hysteresis; budget : float, degrees of mean angle left.
    """
    F, ang = judge.F, judge.weighted_angle
    zones = {}
    best = None
    for name, cand in trials:
        changed = cand != labels
        faces = np.flatnonzero(changed)
        d_angle = float((ang[faces, cand[faces]] - ang[faces, labels[faces]]).sum())
        if not len(faces) or d_angle > budget or (best is not None and d_angle >= best[3]):
            continue
        if ang[faces, cand[faces]].sum() > MAX_MEAN_ANGLE * judge.area[faces].sum():
            continue  # the faces would be labelled across their normals: a wall, not noise
        if _meets_opposite(judge.topology, judge.part, cand, faces):
            continue  # an opposite-label boundary: invalid, no need to judge it
        zkey = faces.tobytes()
        if zkey not in zones:
            vmask = np.zeros(judge.topology.n_vertices, dtype=bool)
            vmask[F[faces]] = True
            zone = judge.zone_of(val.layout, vmask)
            sub = sub_topology(judge.topology, zone)
            zones[zkey] = (vmask, zone, sub, judge.near(val, vmask),
                           _loops_near(sub[0], judge.part[zone], labels[zone], vmask))
        vmask, zone, sub, (inv0, tp0), loops0 = zones[zkey]
        inv1, tp1 = judge.local(cand, zone, vmask, tau, sub, max_invalid=inv0)
        if (tp1 is not None and inv1 <= inv0 and tp1 <= tp0
                and _loops_near(sub[0], judge.part[zone], cand[zone], vmask) <= loops0):
            best = (name, changed, cand, d_angle)
    return best


def _meets_opposite(topology, face_part, labels, faces):
    """Whether any of ``faces`` shares an edge with a face of its part of the opposite label."""
    nb = topology.neighbours[faces]
    other = np.maximum(nb, 0)
    return bool(((nb >= 0) & (face_part[other] == face_part[faces][:, None])
                 & (labels[other] == OPPOSITE[labels[faces]][:, None])).any())


def closed_boundaries(topology, layout):
    """(b,) bool boundaries of ``layout`` that pass no corner (closed loops)."""
    ev = topology.edges[layout.sep_edges]
    at_corner = (layout.vertex_sep_degree[ev[:, 0]] != 2) | (layout.vertex_sep_degree[ev[:, 1]] != 2)
    return np.bincount(layout.sep_boundary, weights=at_corner.astype(np.float64),
                       minlength=layout.n_boundaries) == 0


def _loops_near(sub, face_part, face_label, vmask):
    """Closed boundaries with an edge at ``vmask`` of the labeling ``face_label`` of the zone
    whose topology is ``sub`` (exact as :func:`core.segmentation.validity.local_counts`)."""
    lay = extract_layout(sub, face_part, face_label)
    return int((closed_boundaries(sub, lay) & boundaries_at(sub, lay, vmask)).sum())


def _no_worse(topology, new, old):
    """Whether Validity ``new`` has no more invalid items, turning points and closed boundaries
    than ``old``."""
    return (new.n_invalid <= old.n_invalid
            and len(new.turning_points) <= len(old.turning_points)
            and closed_boundaries(topology, new.layout).sum()
            <= closed_boundaries(topology, old.layout).sum())

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Label changes that let the charts of a valid labeling close as rectilinear polygons.

A labeling can pass the validity rules (every boundary between labels of two axes, every corner
between three) and still have charts that no side directions close
(:mod:`core.quadmesh.polycube.side_signs`): a chart with sides along one of its in-plane axes
on one side only (a triangle where a strut meets a plate or a part interface), or a hole whose
rim has no wall facing one of the four in-plane directions (the label of a neighbouring wall
wraps round it), so the walk round the hole cannot close. Each such chart is the centre of a
neighbourhood (the chart and the charts it shares a side with) whose program alone has no
solution (:func:`~core.quadmesh.polycube.side_signs.contradicting_charts`).

Each round first tries, for every walk with a single side along an axis
(:func:`~core.quadmesh.polycube.side_signs.lone_sides`), its walls relabelled at once
(:func:`~core.quadmesh.polycube.rim_walls.rim_wall_labels`: a hole's rim needs the four
in-plane walls together, which one split at a time never gives). Then it takes the charts in
most of the contradicting neighbourhoods (the *suspects*, at most :data:`MAX_SUSPECTS`) and
tries, on the neighbourhood of each:

- *merges*: the suspect takes the label of one of its neighbours in its part, alone or
  together with one neighbour, or is dissolved into its neighbours face by face;
- *splits*: a connected region of one chart of the neighbourhood whose faces' normals lie
  nearer the direction of a label of another axis than their own takes that label, so the
  wall a hole's rim lacked, or the side a triangle lacked, gets a chart of its own.

A trial is admissible when the faces it changes fit their new labels within
:data:`~core.segmentation.chart_absorption.MAX_MEAN_ANGLE` on average (a wall of the design is
never labelled across its normal; a rim's walls may also fit no worse than before, since a
small hole's wall may face along the hole), the labeling stays valid
(:func:`core.segmentation.validity.check_validity`) and fewer neighbourhoods contradict.
The rims' trials are judged first, then the merges, suspect by suspect, then the splits, each
group of merges and of splits cheapest (least changed area) first, a bounded number per round;
the first admissible trial that adds no turning point is kept, else the first admissible one
(the side directions are chosen anyway). Rounds repeat until no neighbourhood contradicts.
Before them, every chart boundary loop without corners (which no chart complex has) gets
corners the same way, its walls relabelled or, for an island smaller than the charts around
it, the island dissolved. The changed labels are the layout's only: the labeling stage's result
is left as it was.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.errors import LabelingError, OTHER_PARTS
from core.geometry import face_areas, face_cross
from core.quadmesh.polycube.chart_complex import cornerless_rims
from core.quadmesh.polycube.rim_walls import rim_walks, rim_wall_labels
from core.quadmesh.polycube.side_signs import contradicting_charts, lone_sides
from core.segmentation.chart_absorption import MAX_MEAN_ANGLE, dissolved_labels
from core.segmentation.charts import build_topology, extract_layout
from core.segmentation.repair_operators import neighbour_merges
from core.segmentation.validity import check_validity

MAX_ROUNDS = 4
"""Most rounds, each removing at least one contradicting neighbourhood."""
SPLIT_REGIONS = 3
"""Most regions of one chart tried as a split towards one label."""
MAX_SUSPECTS = 4
"""Most charts whose neighbourhoods' trials are judged in one round (the likeliest first)."""
MAX_JUDGED = 200
"""Most trials judged for validity in one round (the cheapest first)."""
MAX_BUILT = 6
"""Most valid trials whose chart complex is built and searched for contradictions in one
round."""


@dataclass(frozen=True)
class ClosableLabels:
    """A labeling whose neighbourhoods all admit side directions, and its chart complex.

    face_label : (m,) int64 labels of the faces the complex was built on.
    complex_ : ChartComplex of those labels.
    changed_area : float, surface area whose label changed (target units squared).
    rounds : int, label changes made (the corners given to loops without any count as one).
    """

    face_label: np.ndarray
    complex_: object
    changed_area: float
    rounds: int


def _label_fit(V, F, face_frame):
    """(m, 6) float64 cosine between each face's normal and each label's direction in its
    frame (+X, -X, +Y, -Y, +Z, -Z)."""
    normal = face_cross(V, F)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    along = np.einsum("mij,mj->mi", face_frame, normal)
    return np.stack([along[:, 0], -along[:, 0], along[:, 1], -along[:, 1], along[:, 2],
                     -along[:, 2]], axis=1)


def _suspects(complex_, bad):
    """(k,) int64 the charts of the contradicting neighbourhoods (``bad``: (b,) int64 their
    centres), those in most of them first, then the smaller: the neighbourhoods of a chart
    that cannot close and of its neighbours all contradict."""
    count = np.zeros(complex_.n_charts, dtype=np.int64)
    for centre in bad.tolist():
        count[_ring(complex_, centre)] += 1
    order = np.lexsort((complex_.chart_area, -count))
    return order[count[order] > 0][:MAX_SUSPECTS]


def _ring(complex_, chart):
    """(k,) int64 ``chart`` then the charts it shares a side with."""
    ring = np.unique(complex_.side_chart[(complex_.side_chart == chart).any(axis=1)])
    return np.concatenate([[chart], ring[ring != chart]]).astype(np.int64)


def _trials(topology, face_part, layout, labels, fit, ring):
    """Candidate labelings for the neighbourhood ``ring`` (centre first, charts of ``layout``).

    Returns ``(merges, splits)``, lists of (m,) int64 labelings: the merges of the centre,
    alone and with one neighbour (:func:`_pair_merges`), and its dissolution into its
    neighbours (each face to the nearest,
    :func:`~core.segmentation.chart_absorption.dissolved_labels`, by the label cost
    ``||n - c_l||^2 = 2 - 2 cos``); the splits of every chart of it, one per connected region
    of its faces that fit another label better than their own (largest first, at most
    :data:`SPLIT_REGIONS` per chart and label).
    """
    merges = [candidate for _, candidate in neighbour_merges(layout, labels, int(ring[0]))]
    merges += _pair_merges(layout, labels, int(ring[0]))
    dissolved = dissolved_labels(topology, face_part, labels, layout.face_chart, int(ring[0]),
                                 2.0 - 2.0 * fit)
    if dissolved is not None:
        merges.append(dissolved)
    splits = []
    own = fit[np.arange(len(labels)), labels]
    for chart in ring.tolist():
        faces = np.flatnonzero(layout.face_chart == chart)
        axis = int(layout.chart_label[chart]) // 2
        for label in range(6):
            if label // 2 == axis:
                continue
            grow = faces[fit[faces, label] > own[faces]]
            if not len(grow) or len(grow) == len(faces):
                continue
            for region in _regions(topology, grow)[:SPLIT_REGIONS]:
                candidate = labels.copy()
                candidate[region] = label
                splits.append(candidate)
    return merges, splits


def _pair_merges(layout, labels, chart):
    """Candidate labelings ((m,) int64 each) that merge ``chart`` together with one of its
    neighbours in its part into each label of the charts around the pair (where the chart
    alone cannot take a neighbour's label without an invalid corner, the pair often can)."""
    out = []
    part = layout.chart_part[chart]
    mine = layout.chart_neighbours[chart].indices
    for other in mine[layout.chart_part[mine] == part].tolist():
        around = np.union1d(mine, layout.chart_neighbours[other].indices)
        around = around[(layout.chart_part[around] == part) & (around != chart)
                        & (around != other)]
        pair = np.isin(layout.face_chart, [chart, other])
        for label in np.unique(layout.chart_label[around]).tolist():
            candidate = labels.copy()
            candidate[pair] = label
            out.append(candidate)
    return out


def _regions(topology, faces):
    """Edge-connected regions of ``faces`` ((k,) int64), largest first, each (j,) int64."""
    inside = np.zeros(len(topology.neighbours), dtype=bool)
    inside[faces] = True
    nb = topology.neighbours[faces]
    keep = (nb >= 0) & inside[np.maximum(nb, 0)]
    local = np.full(len(inside), -1, dtype=np.int64)
    local[faces] = np.arange(len(faces))
    rows = np.repeat(np.arange(len(faces)), nb.shape[1])[keep.reshape(-1)]
    cols = local[nb[keep]]
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(faces), len(faces)))
    n, component = connected_components(graph, directed=False)
    sizes = np.bincount(component, minlength=n)
    return [faces[component == c] for c in np.argsort(-sizes, kind="stable")]


def _fits(candidate, labels, fit, area, lenient=False):
    """True when the faces ``candidate`` changes fit their new labels within
    ``MAX_MEAN_ANGLE`` on average (area-weighted): a wall is never labelled across its
    normal. ``lenient``: also when they fit their new labels no worse than their old ones
    (a hole's wall relabelled by sectors, whose faces may all face along the hole)."""
    changed = np.flatnonzero(candidate != labels)
    weight = area[changed] / max(area[changed].sum(), 1e-300)
    new = np.degrees(np.arccos(np.clip(fit[changed, candidate[changed]], -1.0, 1.0))) @ weight
    old = np.degrees(np.arccos(np.clip(fit[changed, labels[changed]], -1.0, 1.0))) @ weight
    return bool(new <= MAX_MEAN_ANGLE or (lenient and new <= old))


def _round(V, F, face_part, face_frame, topology, labels, fit, area, complex_, bad, turning,
           build, collapsible_of):
    """One round of :func:`closable_labels`: ``(labels, complex_, bad, turning points)`` of
    the kept trial, or None.

    The walls of the rims with a single side along an axis, the merges of each suspect
    (likeliest first), then the splits of all, each group cheapest (least changed area) first,
    are judged for validity (without turning points, up to
    :data:`MAX_JUDGED`), the valid ones by the neighbourhoods that still contradict (up to
    :data:`MAX_BUILT` complexes). The first that
    lowers them and adds no turning point is kept, else the first that lowers them.
    """
    layout = extract_layout(topology, face_part, labels)
    rims = []
    for chart, rim, walls in rim_walks(complex_, lone_sides(complex_, collapsible_of(complex_))):
        rims += rim_wall_labels(V, F, topology, face_part, face_frame, labels,
                                complex_.face_chart, chart, rim, walls, 2.0 - 2.0 * fit)
    rims = [candidate for candidate in rims if _fits(candidate, labels, fit, area, True)]
    merges, splits = [], []
    for suspect in _suspects(complex_, bad).tolist():
        # charts of the complex and of the layout are both the connected faces of one label
        # of one part, numbered alike; mapped through a face all the same
        ring = _ring(complex_, suspect)
        first_face = np.array([np.flatnonzero(complex_.face_chart == c)[0] for c in ring])
        merged, split = _trials(topology, face_part, layout, labels, fit,
                                layout.face_chart[first_face])
        merges.append(merged)
        splits += split
    trials = rims
    for group in merges + [splits]:
        group = [candidate for candidate in group if _fits(candidate, labels, fit, area)]
        costs = [area[candidate != labels].sum() for candidate in group]
        trials += [group[i] for i in np.argsort(costs, kind="stable")]
    fallback, built = None, 0
    for candidate in trials[:MAX_JUDGED]:
        report = check_validity(V, F, face_part, candidate, face_frame, topology,
                                turning=False).report
        if not report["valid"]:
            continue
        try:
            trial = build(candidate)
        except LabelingError:
            continue  # e.g. a boundary loop without corners: no polycube face
        remaining = contradicting_charts(trial, collapsible_of(trial))
        built += 1
        if len(remaining) < len(bad):
            count = check_validity(V, F, face_part, candidate, face_frame,
                                   topology).report["turning_points"]["count"] or 0
            if count <= turning:
                return candidate, trial, remaining, count
            if fallback is None:
                fallback = (candidate, trial, remaining, count)
        if built >= MAX_BUILT:
            break
    return fallback


def _first_with_corners(V, F, face_part, face_frame, topology, labels, fit, area, face_chart,
                        rims):
    """``(labels, face_chart, rims)`` of the first admissible labeling (its changed faces
    fit, it is valid, it has fewer loops without corners) of any of ``rims``, or None.

    Each rim's candidates are its walls relabelled
    (:func:`~core.quadmesh.polycube.rim_walls.rim_wall_labels`; a loop is listed from both of
    its charts, one of which bounds the wall), then, when its chart is smaller than every
    chart across the loop, that chart dissolved into its neighbours (an island a few faces
    across, at the resolution of the mesh, that no walls can square).
    """
    chart_area = np.bincount(face_chart, weights=area)
    for chart, rim, walls in rims:
        candidates = rim_wall_labels(V, F, topology, face_part, face_frame, labels, face_chart,
                                     chart, rim, walls, 2.0 - 2.0 * fit)
        if chart_area[chart] < chart_area[walls].min():
            dissolved = dissolved_labels(topology, face_part, labels, face_chart, chart,
                                         2.0 - 2.0 * fit)
            candidates += [] if dissolved is None else [dissolved]
        for candidate in candidates:
            if not _fits(candidate, labels, fit, area, True) or not check_validity(
                    V, F, face_part, candidate, face_frame, topology,
                    turning=False).report["valid"]:
                continue
            trial_chart, trial_rims = cornerless_rims(F, face_part, candidate)
            if len(trial_rims) < len(rims):
                return candidate, trial_chart, trial_rims
    return None


def _with_corners(V, F, face_part, face_frame, topology, labels, fit, area):
    """``labels`` ((m,) int64) with corners given to every chart boundary loop that admits
    them (a loop left without them makes the chart complex of the result raise).

    Each loop without corners (:func:`~core.quadmesh.polycube.chart_complex.cornerless_rims`)
    is the rim of a wall with one label all round; the first admissible labeling of
    :func:`~core.quadmesh.polycube.rim_walls.rim_wall_labels` (:func:`_first_with_corners`)
    is kept, until none is left or no loop has an admissible one.
    """
    face_chart, rims = cornerless_rims(F, face_part, labels)
    while rims:
        found = _first_with_corners(V, F, face_part, face_frame, topology, labels, fit, area,
                                    face_chart, rims)
        if found is None:
            break
        labels, face_chart, rims = found
    return labels


class UnclosableChartsError(LabelingError):
    """Neighbourhoods of charts that admit no side directions remain and no admissible label
    change removes one (:func:`closable_labels`)."""


def closable_labels(V, F, face_part, face_label, face_frame, build, collapsible_of):
    """Change the labels of the charts that no side directions close, keeping them valid.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64 the surface the complex is built on.
    face_part, face_label : (m,) int64; face_frame : (m, 3, 3) float64 rows x, y, z.
    build : callable, (m,) int64 labels -> ChartComplex of them.
    collapsible_of : callable, ChartComplex -> (s,) bool sides allowed length zero.

    Returns
    -------
    ClosableLabels: every neighbourhood admits side directions (the whole labeling may still
    have none: the caller finds out).

    Raises
    ------
    LabelingError from ``build`` on the labels with corners given to every loop that admits
    them: a :class:`~core.quadmesh.polycube.chart_complex.CornerlessLoopError` naming a loop
    that no admissible trial gives corners (and what it runs round), or a boundary between
    opposite labels; UnclosableChartsError when no admissible trial removes a contradicting
    neighbourhood (within :data:`MAX_ROUNDS` rounds), naming them.
    """
    face_part = np.asarray(face_part, dtype=np.int64)
    labels = np.asarray(face_label, dtype=np.int64).copy()
    topology = build_topology(F, len(V))
    fit = _label_fit(V, F, face_frame)
    area = face_areas(V, F)
    before = check_validity(V, F, face_part, labels, face_frame, topology).report
    turning = before["turning_points"]["count"] or 0
    original = labels
    labels = _with_corners(V, F, face_part, face_frame, topology, labels, fit, area)
    changed = labels != original
    rounds = int(changed.any())
    complex_ = build(labels)
    bad = contradicting_charts(complex_, collapsible_of(complex_))
    while len(bad) and rounds < MAX_ROUNDS:
        found = _round(V, F, face_part, face_frame, topology, labels, fit, area, complex_, bad,
                       turning, build, collapsible_of)
        if found is None:
            break
        candidate, complex_, bad, turning = found
        changed |= candidate != labels
        labels = candidate
        rounds += 1
    if len(bad):
        raise UnclosableChartsError(
            f"the neighbourhoods of {len(bad)} charts (e.g. charts {bad[:5].tolist()}) admit no "
            f"side directions and no admissible label change closes them (after {rounds} "
            f"label changes). The labeling is not a polycube there: try {OTHER_PARTS} or "
            f"another labeling")
    return ClosableLabels(labels, complex_, float(area[changed].sum()), rounds)

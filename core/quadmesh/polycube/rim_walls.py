# SPDX-License-Identifier: LGPL-2.1-or-later
"""Labels that give the rim of a hole in a chart its four walls at once.

A hole through a thin wall, or a slot between two members, is bounded in the chart it pierces
(label along axis ``a``) by a *rim*: a walk of sides between that chart and the hole's walls.
The walk closes as a rectilinear polygon only with sides in both directions along both in-plane
axes ``u`` and ``v``, i.e. with walls facing ``+u``, ``-u``, ``+v`` and ``-v``
(:func:`~core.quadmesh.polycube.side_signs.lone_sides`). When the labeling stage gave a small
round hole's wall one label all round, or let a member's side wrap round the end of a slot, one
or two of these walls are missing, and no single split adds them without another one missing
(the walk still has a single side along an axis after each).

:func:`rim_wall_labels` relabels the hole's wall in one move: the faces of the charts across the
rim that lie over the rim's bounding rectangle (in the ``u, v`` plane of the pierced chart,
within a margin) and are connected to the rim through such faces take the label of the side of
that rectangle they lie nearest to, facing into the hole (or out of it, around a boss: the
side the faces' normals point to on average). The rectangle's straight skeleton splits a tube
into four sectors, each a chart with one side on the rim, so the rim becomes a rectangle of four
sides. Further candidates relabel only the faces whose sector's label no wall of the rim has,
in sectors as they are and thinned (the distance to a missing side weighted by
:data:`THINNING`: the tapered end of a slot between two members is walled by a narrow strip,
not by the members' sides). A changed face that would meet a face of the opposite label keeps
its label, a piece of a chart that the changes cut off and leave with fewer than four
boundaries (invalid by :mod:`core.segmentation.validity`) is joined back to its chart by the
shortest path of changed faces that had its label, and a chart of fewer than four boundaries
that is still left (a sliver between sectors) is dissolved into its neighbours.

The same move gives corners to a chart boundary loop that passes none (a wall with one label
all round, :func:`~core.quadmesh.polycube.chart_complex.cornerless_rims`).
"""
import numpy as np

from core.geometry import face_cross
from core.quadmesh.polycube.side_signs import chart_walks
from core.segmentation.chart_absorption import dissolved_labels
from core.segmentation.charts import extract_layout

RIM_MARGIN = 0.25
"""Faces whose centre lies within this fraction of the rim rectangle's smaller extent outside
the rectangle count as the hole's wall (a wall that flares away from the rim)."""
TIDY_ROUNDS = 4
"""Most rounds of giving back conflicting changes and dissolving the small charts left."""
THINNING = 3.0
"""Weight of the distance to a wall the rim lacks in the thinned candidate."""


def rim_walks(complex_, lone):
    """The walks that a single side along an axis keeps from closing.

    Parameters
    ----------
    complex_ : ChartComplex
    lone : list of ``(chart, hole, axis, side)`` as
        :func:`~core.quadmesh.polycube.side_signs.lone_sides` returns.

    Returns
    -------
    list of ``(chart, rim, walls)``: the chart, (k,) int64 the vertices of the shortest of
    its walks (:func:`~core.quadmesh.polycube.side_signs.chart_walks`) holding the lone side
    and (j,) int64 the charts across that walk (slit sides left out); one per walk.
    """
    walks = []
    for walk, hole in chart_walks(complex_):
        loop = np.searchsorted(complex_.loop_offsets, walk[0], side="right") - 1
        refs = complex_.loop_sides[walk]
        sides = np.where(refs >= 0, refs, ~refs)
        plain = sides[complex_.side_chart[sides, 0] != complex_.side_chart[sides, 1]]
        walks.append((int(complex_.loop_chart[loop]), bool(hole), np.unique(plain)))
    out, seen = [], set()
    for chart, hole, _, side in lone:
        holding = [sides for c, h, sides in walks if c == chart and h == hole and side in sides]
        if not holding:
            continue
        best = min(holding, key=len)
        key = (chart, tuple(best.tolist()))
        if key not in seen:
            seen.add(key)
            rim = np.unique(np.concatenate([complex_.chain(s) for s in best.tolist()]))
            walls = np.unique(complex_.side_chart[best])
            out.append((int(chart), rim, walls[walls != chart]))
    return out


def rim_wall_labels(V, F, topology, face_part, face_frame, labels, face_chart, chart, rim,
                    walls, cost):
    """Candidate labelings that give a rim the four walls it needs.

    Parameters
    ----------
    V : (n, 3) float64, F : (m, 3) int64 the labelled surface; topology : MeshTopology of F.
    face_part : (m,) int64; face_frame : (m, 3, 3) float64 rows x, y, z; labels : (m,) int64.
    face_chart : (m,) int64 the charts of ``labels`` (connected faces of one part and label).
    chart : int the chart the rim bounds; rim : (k,) int64 its vertices; walls : (j,) int64
        the charts across it.
    cost : (m, 6) float64 cost of each label for each face (``||n - c_l||^2``), by which a
        chart of fewer than four boundaries that the change leaves is dissolved.

    Returns
    -------
    list of distinct (m,) int64 labelings that differ from ``labels``: every wall face
    relabelled by its sector, then only those whose sector's label no wall of the rim has (as
    they are, then thinned); empty when the rim has no wall faces.
    """
    faces = np.flatnonzero(face_chart == chart)
    axis = int(labels[faces[0]]) // 2
    u_axis, v_axis = [k for k in range(3) if k != axis]
    frame = face_frame[faces[0]]
    first = np.array([np.flatnonzero(face_chart == w)[0] for w in walls.tolist()], dtype=np.int64)
    same_part = face_part[first] == face_part[faces[0]]
    walls, wall_labels = walls[same_part], labels[first[same_part]]
    uv = V @ frame[[u_axis, v_axis]].T  # (n, 2) in-plane coordinates
    low, high = uv[rim].min(axis=0), uv[rim].max(axis=0)
    margin = RIM_MARGIN * float((high - low).min())
    centre_uv = uv[F].mean(axis=1)
    over = np.all((centre_uv >= low - margin) & (centre_uv <= high + margin), axis=1)
    seed = np.isin(F, rim).any(axis=1)
    region = _connected_from(topology, np.isin(face_chart, walls) & over, seed)
    if not len(region):
        return []
    # distance to the rectangle's four walls: low u, high u, low v, high v
    p = centre_uv[region]
    gap = np.stack([p[:, 0] - low[0], high[0] - p[:, 0], p[:, 1] - low[1], high[1] - p[:, 1]],
                   axis=1)
    # a wall at low u faces +u into a hole (-u round a boss): the faces' normals say which
    normal = face_cross(V, F[region]) @ frame[[u_axis, v_axis]].T
    inward = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    hole = np.einsum("kj,kj->", normal, inward[np.argmin(gap, axis=1)]) >= 0.0
    wall_label = (np.array([2 * u_axis, 2 * u_axis, 2 * v_axis, 2 * v_axis])
                  + ((np.arange(4) % 2 == 1) == hole))
    missing = ~np.isin(wall_label, wall_labels)
    out = []
    for thinning, only_missing in ((1.0, False), (1.0, True), (THINNING, True)):
        if only_missing and not missing.any():
            continue
        nearest = np.argmin(gap * np.where(missing, thinning, 1.0), axis=1)
        keep = missing[nearest] if only_missing else np.ones(len(region), dtype=bool)
        candidate = labels.copy()
        candidate[region[keep]] = wall_label[nearest[keep]]
        candidate = _tidied(topology, face_part, labels, candidate, seed)
        for _ in range(TIDY_ROUNDS):
            joined = _tidied(topology, face_part, labels,
                             _remnants_joined(topology, face_part, labels, candidate), seed)
            dissolved = _without_small_charts(topology, face_part, labels, joined, cost)
            if np.array_equal(dissolved, candidate):
                break
            candidate = _tidied(topology, face_part, labels, dissolved, seed)
        if (candidate != labels).any() and not any(np.array_equal(candidate, c) for c in out):
            out.append(candidate)
    return out


def _tidied(topology, face_part, labels, candidate, seed):
    """``candidate`` ((m,) int64) with the changes that would break the labeling given back
    their label in ``labels``, until none is left: a changed face that meets a face of the
    opposite label, and the changed faces of a chart all of whose faces changed and none of
    which touches ``seed`` ((m,) bool, the faces at the rim): a fragment of a sector."""
    candidate = candidate.copy()
    while True:
        changed = np.flatnonzero(candidate != labels)
        if not len(changed):
            return candidate
        nb = topology.neighbours[changed]
        opposite = (nb >= 0) & (candidate[np.maximum(nb, 0)] == (candidate[changed] ^ 1)[:, None])
        back = changed[opposite.any(axis=1)]
        if not len(back):
            face_chart = extract_layout(topology, face_part, candidate).face_chart
            anchored = np.zeros(int(face_chart.max()) + 1, dtype=bool)
            anchored[face_chart[(candidate == labels) | seed]] = True
            back = changed[~anchored[face_chart[changed]]]
            if not len(back):
                return candidate
        candidate[back] = labels[back]


def _remnants_joined(topology, face_part, labels, candidate):
    """``candidate`` ((m,) int64) with every *remnant* joined back to the chart it was cut from.

    A remnant is a chart of fewer than four boundaries (invalid,
    :mod:`core.segmentation.validity`) whose faces all keep their label in ``labels``: a
    piece of a chart that the changed faces around it cut off, e.g. a face of the wall
    left between two opposite sectors where a slot tapers (dissolving it into either sector
    would make them meet). The changed faces on the shortest edge path, through faces
    whose label in ``labels`` was the remnant's, from the remnant to another face of that
    label that kept it take their label back; a remnant with no such path is left as it is.
    """
    layout = extract_layout(topology, face_part, candidate)
    changed = candidate != labels
    small = np.flatnonzero(layout.chart_boundary_count <= 3)
    out = candidate.copy()
    for chart in small.tolist():
        faces = np.flatnonzero(layout.face_chart == chart)
        if changed[faces].any():
            continue
        label = int(candidate[faces[0]])
        before = np.full(len(labels), -2, dtype=np.int64)
        before[faces] = -1
        frontier, reached = faces, -1
        while len(frontier) and reached < 0:
            nb = topology.neighbours[frontier]
            src = np.repeat(frontier, nb.shape[1])
            nb = nb.reshape(-1)
            ok = ((nb >= 0) & (labels[np.maximum(nb, 0)] == label)
                  & (face_part[np.maximum(nb, 0)] == face_part[faces[0]]))
            src, nb = src[ok], nb[ok]
            fresh = before[nb] == -2
            src, nb = src[fresh], nb[fresh]
            nb, first = np.unique(nb, return_index=True)
            before[nb] = src[first]
            kept = nb[~changed[nb]]
            if len(kept):
                reached = int(kept[0])
            frontier = nb[changed[nb]]
        face = before[reached] if reached >= 0 else -1
        while face >= 0 and changed[face]:
            out[face] = labels[face]
            face = before[face]
    return out


def _without_small_charts(topology, face_part, labels, candidate, cost):
    """``candidate`` ((m,) int64) with every chart of fewer than four boundaries (invalid,
    :mod:`core.segmentation.validity`) at or next to a face it changes from ``labels``
    dissolved into its neighbours
    (:func:`~core.segmentation.chart_absorption.dissolved_labels`, by ``cost``)."""
    layout = extract_layout(topology, face_part, candidate)
    changed = np.flatnonzero(candidate != labels)
    near = topology.neighbours[changed].reshape(-1)
    touched = np.unique(layout.face_chart[np.concatenate([changed, near[near >= 0]])])
    small = touched[layout.chart_boundary_count[touched] <= 3]
    out = candidate
    for chart in small[np.argsort(layout.chart_size[small], kind="stable")].tolist():
        dissolved = dissolved_labels(topology, face_part, out, layout.face_chart, chart, cost)
        if dissolved is not None:
            out = dissolved
    return out


def _connected_from(topology, allowed, seed):
    """(k,) int64 the ``allowed`` faces ((m,) bool) edge-connected through allowed faces to an
    allowed face of ``seed`` ((m,) bool)."""
    reached = allowed & seed
    frontier = np.flatnonzero(reached)
    while len(frontier):
        nb = topology.neighbours[frontier].reshape(-1)
        nb = np.unique(nb[nb >= 0])
        nb = nb[allowed[nb] & ~reached[nb]]
        reached[nb] = True
        frontier = nb
    return np.flatnonzero(reached)

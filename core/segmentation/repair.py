# SPDX-License-Identifier: LGPL-2.1-or-later
"""Automatic repair of an invalid polycube labeling (deterministic operator loop).

Ideas from "validity-first polycube labeling" (Mestrallet, Bourcier, Ledoux 2025): apply local
operators, each aimed at one kind of invalid item, and re-judge after every round until the
labeling is valid, nothing changes, a state repeats or the round cap is hit. Operators, in order
of priority (one kind per round, so every round works on a fresh judgement):

1. *Opposite-label boundaries* (+X next to -X): trial candidates for the first such boundary
   are merging either of its two charts into one of that chart's neighbouring labels, and the strip
   insertion below for all of them; the candidate with the fewest invalid items (then smallest mean
   angle, within the angle budget) is kept if it lowers the invalid count, else the strip insertion
   is applied anyway. Strip insertion: the faces of both charts touching the boundary's
   vertices form a strip; the strip takes the perpendicular label (axis different from the two
   opposite labels) of least normal cost ``sum ||n - c_l||^2`` and not opposite to a label the
   strip already touches, so the two charts end up separated by a chart of a third axis.
2. *Labels parallel to an interface x-axis* (multi-part only): the offending side's faces touching
   the interface boundary take the least-cost label that is not parallel to the interface axis
   (kept only if it lowers the invalid count; otherwise the next operators run).
3. *Invalid charts* (three or fewer boundaries), smallest first, an independent set per round
   (no two chosen charts touch, so each decision sees its neighbours' final labels): the chart is
   relabelled to the neighbouring chart label of least normal cost among those that are not
   opposite to any label around the chart, so the chart merges into that neighbour without
   creating an opposite boundary. Without such a label it takes the least-cost neighbour label.
4. *One-axis corners* (all separating edges at the vertex share one axis, e.g. a fan +X, +Y, -X,
   -Y: opposite labels touching at a point) left after 1-3: the faces of the part within two
   vertex rings take the label of that axis (the sign of least normal cost), a new chart that
   shares a boundary with each chart of the fan and has X, Y, Z corners (kept if it lowers the
   invalid count within the angle budget).
5. *Invalid corners* left after 1-4 (mostly at part interfaces): the faces of the part around the
   corner vertex whose labels break the corner rule take the label of their largest neighbouring
   chart.

After each merge round a boundary-smoothing pass runs the HBECVT sweeps restricted to the faces
that touch a separating edge, with the extra rule that a face may only take a label already present
among its neighbours (boundaries move, charts are neither created nor split off by it); this undoes
the jagged edges merges leave. Everything is vectorised per round; the loop is deterministic.

Candidates are scored on the submesh around the faces they change (exact; see
:func:`core.segmentation.validity.local_invalid_count`); only accepted states are judged whole.
Per-chart trials are capped (``max_trials``) and so are consecutive sideways moves
(``max_sideways``), so the work stays bounded on meshes with many invalid charts.
"""
import numpy as np

from core.errors import ParameterError
from core.geometry import face_areas
from core.segmentation.charts import OPPOSITE, build_topology
from core.segmentation.labeling import (LAMBDA, PENALTY, check_frames, face_colouring,
                                        face_normals, hbecvt_sweeps, interface_penalty,
                                        label_cost, label_vectors, part_neighbours)
from core.segmentation.parts import face_interface_axes, interfaces
from core.segmentation.validity import (COS_45, check_validity, counts_near, edge_interface_axes,
                                        local_counts, local_invalid_count, with_turning_points)
from core.types import TriMesh


def _chart_costs(cost, face_chart, n_charts):
    """(c, 6) summed label cost of every chart."""
    return np.stack([np.bincount(face_chart, weights=cost[:, l], minlength=n_charts)
                     for l in range(6)], axis=1)


def _faces_at_vertices(F, vertex_mask):
    return vertex_mask[F[:, 0]] | vertex_mask[F[:, 1]] | vertex_mask[F[:, 2]]


def _fix_opposite(F, topology, val, labels, cost):
    lay = val.layout
    bad = np.flatnonzero(val.boundary_reason == 1)
    edge_bad = np.isin(lay.sep_boundary, bad)
    vmask = np.zeros(topology.n_vertices, dtype=bool)
    vmask[topology.edges[lay.sep_edges[edge_bad]].reshape(-1)] = True
    charts = lay.boundary_charts[bad]
    chart_of_b = np.full(lay.n_charts, -1, dtype=np.int64)
    # each chart joins the strip of the first (lowest id) opposite boundary it lies on
    for col in (1, 0):
        chart_of_b[charts[::-1, col]] = bad[::-1]
    strip_b = chart_of_b[lay.face_chart]
    in_strip = _faces_at_vertices(F, vmask) & (strip_b >= 0)
    faces = np.flatnonzero(in_strip)
    group = strip_b[faces]
    new = labels.copy()
    groups, inv = np.unique(group, return_inverse=True)
    gcost = _chart_costs(cost[faces], inv.reshape(-1), len(groups))
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
    return new, len(groups)


def _fix_interface(F, topology, val, labels, cost, face_part, face_frame, iface_pen, edge_ix):
    """Relabel faces whose label is parallel to a part interface's x-axis.

    Two sets of faces change: faces next to the invalid interface boundaries whose label carries
    Eq. 3's interface penalty, and the faces on interface edges whose label direction lies within
    45 degrees of that edge's loop axis (the rule of :func:`check_validity`). Each takes its
    least-cost label that is neither penalised nor within 45 degrees of the axis.
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
    wrong = forbid[np.arange(m), labels] & _faces_at_vertices(F, vmask)
    faces = np.flatnonzero(wrong)
    new = labels.copy()
    new[faces] = np.argmin(cost[faces] + 1e3 * forbid[faces], axis=1)
    return new, len(bad)


def _merge_charts(val, labels, cost, which):
    lay = val.layout
    bad = np.flatnonzero(which)
    order = bad[np.lexsort((bad, lay.chart_size[bad]))]
    nbm = lay.chart_neighbours
    ccost = _chart_costs(cost, lay.face_chart, lay.n_charts)
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
    return new, len(chosen)


def _one_axis_corners(topology, val):
    """Invalid corners whose separating edges all have one and the same axis (e.g. a fan
    +X, +Y, -X, -Y around the vertex: four edges along Z), and that axis: (k,) int64 each."""
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
    return corners[one], lo[corners[one]]


def _fix_one_axis_corners(F, topology, labels, face_part, cost, corners, axes, rings=2):
    """Insert a chart of the corners' common axis: the faces of the corner's part within
    ``rings`` vertex rings of each corner take that axis' label of least normal cost, so the
    charts that met at a point (pairwise opposite across it) now each share a boundary with the
    new chart, whose corners are X, Y, Z groups."""
    new = labels.copy()
    for v, k in zip(corners.tolist(), axes.tolist()):
        vmask = np.zeros(topology.n_vertices, dtype=bool)
        vmask[v] = True
        for _ in range(rings):
            vmask[F[_faces_at_vertices(F, vmask)]] = True
        part_of_corner = face_part[np.flatnonzero(F == v)[0] // 3]
        faces = np.flatnonzero(_faces_at_vertices(F, vmask) & (face_part == part_of_corner))
        plus, minus = cost[faces, 2 * k].sum(), cost[faces, 2 * k + 1].sum()
        new[faces] = 2 * k if plus <= minus else 2 * k + 1
    return new, len(corners)


def _fix_corners(F, topology, val, labels, face_part):
    lay = val.layout
    vmask = np.zeros(topology.n_vertices, dtype=bool)
    vmask[val.invalid_corners] = True
    faces = np.flatnonzero(_faces_at_vertices(F, vmask))
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
    return new, int(big.sum())


def _boundary_faces(topology, face_part, labels):
    """(m,) bool faces with an edge neighbour in another chart (other label or other part)."""
    tn = topology.neighbours
    ok = tn >= 0
    other = np.maximum(tn, 0)
    diff = ok & ((labels[other] != labels[:, None]) | (face_part[other] != face_part[:, None]))
    return diff[:, 0] | diff[:, 1] | diff[:, 2]


def _smooth_boundaries(labels, active, unary, nb, colour, lam, penalty):
    """HBECVT sweeps on the ``active`` faces (those next to separating edges), labels limited to
    the labels of each face's neighbours."""
    has = nb >= 0
    present = np.zeros((len(labels), 6), dtype=bool)
    rows = np.repeat(np.arange(len(labels)), nb.shape[1])[has.reshape(-1)]
    present[rows, labels[nb[has]]] = True
    present[np.arange(len(labels)), labels] = True
    restricted = np.where(present, unary, unary + 4.0 * penalty)
    out, _ = hbecvt_sweeps(restricted, nb, labels, colour, lam, penalty, max_sweeps=3,
                           active=active)
    return out.astype(np.int64)


def _local_resegment(labels, unary, nb, colour, region, lam, penalty):
    """Re-run the HBECVT sweeps inside ``region`` from nearest-direction labels with ``lam``."""
    start = labels.copy()
    start[region] = np.argmin(unary[region], axis=1)
    out, _ = hbecvt_sweeps(unary, nb, start, colour, lam, penalty, max_sweeps=50, active=region)
    return out.astype(np.int64)


class CandidateJudge:
    """Validity and mean-angle bookkeeping for candidate labelings.

    :meth:`validity` judges a whole labeling; :meth:`delta` judges a candidate against the current
    labeling on the submesh around the faces it changes (see
    :func:`core.segmentation.validity.local_invalid_count`), which is exact and much cheaper on
    large meshes. The interface axes depend on the parts only and are computed once. One judge
    serves the repair and the monotonicity pass of a labeling: the last :data:`MEMO` whole-mesh
    judgements are kept, so a labeling judged once (a candidate, then the state it becomes) is not
    judged again.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; face_part : (m,) int64; face_frame : (m, 3, 3) float64.
    topology : MeshTopology.
    cost : (m, 6) float64 ``||n - c_l||^2`` (:func:`core.segmentation.labeling.label_cost`).
    area : (m,) float64 face areas.
    edge_ix : (e, 3) float64, optional interface x-axes per edge
        (:func:`core.segmentation.validity.edge_interface_axes`, computed when omitted).
    """

    MEMO = 8
    """Whole-mesh judgements kept."""

    def __init__(self, V, F, face_part, face_frame, topology, cost, area, edge_ix=None):
        self.V, self.F, self.part = V, F, face_part
        self.face_frame = face_frame
        self.topology = topology
        self.cost = cost
        self.area = area / area.sum()
        # (m, 6) angle of every label times the face's area share: sums to the mean angle
        self.weighted_angle = (np.degrees(np.arccos(np.clip(1.0 - 0.5 * cost, -1.0, 1.0)))
                               * self.area[:, None])
        self.edge_ix = edge_interface_axes(V, topology, face_part) if edge_ix is None else edge_ix
        self._memo = []

    @classmethod
    def of_mesh(cls, V, F, face_part, face_frame, topology, normals=None, edge_ix=None):
        """The judge of a mesh, its parts and frames, with the label cost from its unit face
        ``normals`` ((m, 3) float64, computed when omitted)."""
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        normals = face_normals(V, F) if normals is None else normals
        return cls(V, F, np.asarray(face_part, dtype=np.int64), face_frame, topology,
                   label_cost(normals, face_frame), face_areas(V, F), edge_ix)

    def validity(self, labels, tau=None):
        """Validity of ``labels`` on the whole mesh; with ``tau`` (hysteresis, mesh units) also
        its turning points (:func:`core.segmentation.validity.check_validity`)."""
        found = next((v for lab, v in self._memo if np.array_equal(lab, labels)), None)
        if found is None:
            found = check_validity(self.V, self.F, self.part, labels, self.face_frame,
                                   self.topology, turning=False, edge_interface_axis=self.edge_ix)
        if tau is not None and found.report["turning_points"]["tolerance"] != tau:
            found = with_turning_points(self.V, self.topology, self.face_frame, found, tau)
        self._memo = [(np.array(labels), found)] + [
            (lab, v) for lab, v in self._memo if not np.array_equal(lab, labels)][:self.MEMO - 1]
        return found

    def zone(self, labels, lay, cand):
        """Submesh faces (sorted) and changed-vertex mask for judging ``cand`` against
        ``labels`` (whose layout is ``lay``): the charts touching a changed vertex plus the faces
        around their vertices."""
        vmask = np.zeros(self.topology.n_vertices, dtype=bool)
        vmask[self.F[cand != labels]] = True
        return self.zone_of(lay, vmask), vmask

    def zone_of(self, lay, vmask):
        """(s,) int64 sorted submesh faces for judging changes of faces whose vertices all lie in
        ``vmask`` against a labeling of layout ``lay`` (see :meth:`zone`)."""
        F = self.F
        charts = np.zeros(lay.n_charts, dtype=bool)
        charts[lay.face_chart[_faces_at_vertices(F, vmask)]] = True
        vz = np.zeros_like(vmask)
        vz[F[charts[lay.face_chart]]] = True
        return np.flatnonzero(_faces_at_vertices(F, vz))

    def delta(self, labels, val, cand):
        """(change of the invalid-item count from ``labels`` (judged as ``val``) to ``cand``,
        opposite-label boundaries of ``cand`` near its changes, or on the whole mesh when the
        zone holds more than half of it: such candidates are judged whole). The items of
        ``labels`` near the changes are read off ``val``
        (:func:`core.segmentation.validity.counts_near`)."""
        lay = val.layout
        faces, vmask = self.zone(labels, lay, cand)
        if 2 * len(faces) > len(labels):
            full = self.validity(cand)
            return full.n_invalid - val.n_invalid, int((full.boundary_reason == 1).sum())
        old = counts_near(self.F, self.topology, val, vmask)[:4]
        new = local_invalid_count(self.F, self.topology, self.part, cand, self.face_frame,
                                  self.edge_ix, faces, vmask)
        return sum(new[:3]) - sum(old[:3]), new[3]

    def local(self, labels, faces, vmask, tau, sub=None, max_invalid=None):
        """(invalid items, turning points (hysteresis ``tau``)) of ``labels`` touching ``vmask``,
        judged on the zone ``faces`` of :meth:`zone_of` (exact differences between labelings that
        differ only on faces with all vertices in ``vmask``, see
        :func:`core.segmentation.validity.local_counts`; ``sub`` its submesh topology; the turning
        points are None when the invalid items exceed ``max_invalid``)."""
        c = local_counts(self.V, self.F, self.topology, self.part, labels, self.face_frame,
                         self.edge_ix, faces, vmask, tau, sub, max_invalid)
        return sum(c[:3]), c[4]

    def near(self, val, vmask):
        """(invalid items, turning points) touching ``vmask`` of the labeling judged as ``val``:
        what :meth:`local` gives for it on a zone of :meth:`zone_of` (``val.layout``, ``vmask``),
        read off the whole-mesh judgement (:func:`core.segmentation.validity.counts_near`)."""
        c = counts_near(self.F, self.topology, val, vmask)
        return sum(c[:3]), c[4]

    def angle(self, labels):
        """Area-weighted mean angle in degrees between normals and the label directions."""
        return float(self.weighted_angle[np.arange(len(labels)), labels].sum())


def _chart_candidates(F, face_part, val, labels, c, cost, unary, nb, colour, penalty, lams):
    """Candidate labelings that change invalid chart ``c``: merges into each neighbouring label;
    for each label of another axis missing around the chart, the faces of the chart and its
    neighbouring charts that fit that label better than their own take it; growing the chart
    over the faces of its part around its corners (so it gains a boundary with every chart that
    only touched it at a corner) and over its one-ring; local re-segmentations of the chart and
    its neighbours at coarser ``lam``."""
    lay = val.layout
    nbrs = lay.chart_neighbours[c].indices
    nbrs = nbrs[lay.chart_part[nbrs] == lay.chart_part[c]]
    in_c = lay.face_chart == c
    out = []
    for lab in np.unique(lay.chart_label[nbrs]).tolist():
        cand = labels.copy()
        cand[in_c] = lab
        out.append((f"merge_into_{lab}", cand))
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
            out.append((f"grow_missing_{lab}", cand))
    own_part = face_part == lay.chart_part[c]
    ring = np.zeros(len(lay.vertex_sep_degree), dtype=bool)
    ring[F[in_c]] = True
    at_corner = ring & (lay.vertex_sep_degree >= 3)
    for name, vmask in (("grow_at_corners", at_corner), ("grow_ring", ring)):
        grow = _faces_at_vertices(F, vmask) & own_part & ~in_c
        if grow.any():
            cand = labels.copy()
            cand[grow] = a
            out.append((name, cand))
    for lam in lams:
        out.append((f"resegment_lambda_{lam:g}", _local_resegment(labels, unary, nb, colour,
                                                                   region, lam, penalty)))
    return out


def _joint_merges(lay, labels, c, small_chart):
    """Candidates that merge invalid chart ``c`` together with its small neighbouring charts of
    its part (at most ``small_chart`` faces) into each label around that group: where a small
    chart of the opposite label sits between ``c`` and a large neighbour, merging either alone
    leaves an opposite-label boundary (tried when no candidate of :func:`_chart_candidates`
    helps). Returns a list of (name, labels)."""
    part = lay.chart_part[c]
    nbrs = lay.chart_neighbours[c].indices
    nbrs = nbrs[lay.chart_part[nbrs] == part]
    small = nbrs[lay.chart_size[nbrs] <= small_chart]
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
        out.append((f"merge_with_small_into_{lab}", cand))
    return out


def repair_labeling(V, F, face_part, face_label, face_frame, face_interface_axis=None,
                    max_rounds=60, smooth=True, max_angle_increase=4.0, small_chart=None,
                    lam=LAMBDA, penalty=PENALTY, topology=None, max_trials=None,
                    max_sideways=4, colour=None, judge=None):
    """Drive the invalid charts, boundaries and corners of a labeling towards zero.

    Parameters
    ----------
    V : (n, 3) float64 vertices.
    F : (m, 3) int faces.
    face_part : (m,) int part of each face.
    face_label : (m,) int labels 0..5 to repair (not modified).
    face_frame : (m, 3, 3) float64 per-face frames (rows x, y, z).
    face_interface_axis : (m, 3) float64, optional interface x-axis next to interfaces, NaN
        elsewhere (Eq. 3 term 4 in smoothing and re-segmentation); when omitted, the frames'
        own (:func:`core.segmentation.parts.face_interface_axes`).
    max_rounds : int, cap on operator rounds.
    smooth : bool, run the restricted boundary smoothing after merges.
    max_angle_increase : float, degrees; no chart operation may raise the area-weighted mean
        angle between normals and label directions above the input's plus this.
    small_chart : int, charts with at most this many faces are merged in batches without a
        per-chart trial (default ``max(10, m // 2000)``).
    lam, penalty : float, Eq. 3 parameters used by smoothing and re-segmentation.
    topology : MeshTopology, optional.
    max_trials : int, cap on per-chart candidate evaluations over the whole repair (default
        ``max(200, 2000000 // m)``: bounded work per mesh; hard multi-part cases need ~200).
    max_sideways : int, cap on consecutive moves that keep the invalid count (new states only).
    colour : (m,) int64, optional :func:`face_colouring` of the part neighbours (computed when
        omitted; the labeling computes the same one).
    judge : CandidateJudge, optional, of this mesh, parts and frames (built when omitted; the
        labeling stage passes one to the repair and then to the monotonicity pass).

    Returns
    -------
    labels : (m,) int32 repaired labels.
    report : dict with ``rounds``, ``valid``, ``stopped`` (``valid``, ``stuck`` or
        ``round_cap``), ``operations`` (per-round operator and item count), ``before`` and
        ``after`` (the validity reports, without turning points: the monotonicity pass counts them), ``angle_before`` /
        ``angle_after`` (area-weighted mean degrees), ``gave_up`` (charts no candidate
        improved: example face, label, faces) and ``unfixed`` (the remaining invalid items with
        examples, empty when valid).

    Notes
    -----
    Invalid charts are handled in two ways. Small ones (``small_chart``) are merged in batches as
    in operator 3 of the module docstring; a batch is kept only if it lowers the invalid count.
    Otherwise each invalid chart, smallest first, gets trial candidates: merging it into each
    neighbouring label, growing it over the faces of its part around its corners or over its
    one-ring (a chart that touched a neighbour only at a corner gains a boundary with it; this
    fixes the small charts automatic parts leave along interfaces), and re-running the HBECVT
    sweeps on the chart plus its neighbouring charts from nearest-direction labels with
    lambda = 1, 2, 4, 8 (a coarser local segmentation). The
    candidate with the fewest invalid items (then the smallest mean angle) is kept if it has fewer
    invalid items than now and respects the angle budget; a chart with no such candidate is given
    up and reported.
    """
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    if int(max_rounds) < 0:
        raise ParameterError(f"max_rounds must be >= 0, got {max_rounds}")
    if not max_angle_increase >= 0:
        raise ParameterError(f"max_angle_increase must be >= 0, got {max_angle_increase}")
    face_part = np.asarray(face_part, dtype=np.int64)
    labels = np.asarray(face_label, dtype=np.int64).copy()
    if labels.shape != (m,) or face_part.shape != (m,):
        raise ParameterError(f"face_label and face_part must have shape ({m},)")
    if len(labels) and (labels.min() < 0 or labels.max() > 5):
        bad = np.flatnonzero((labels < 0) | (labels > 5))
        raise ParameterError(f"face_label has {len(bad)} values outside 0..5 "
                             f"(e.g. face {int(bad[0])}: {int(labels[bad[0]])})")
    if topology is None:
        topology = build_topology(F, len(V))
    if small_chart is None:
        small_chart = max(10, m // 2000)
    if max_trials is None:
        max_trials = max(200, 2000000 // max(m, 1))
    V = np.asarray(V, dtype=np.float64)
    if judge is None:
        judge = CandidateJudge.of_mesh(V, F, face_part, check_frames(face_frame, m), topology)
    face_frame, cost = judge.face_frame, judge.cost
    if face_interface_axis is None and face_part.max(initial=0) > 0:
        itfs = interfaces(TriMesh(V, F), face_part)
        face_interface_axis = face_interface_axes(F, face_part, itfs, V)[1]
    iface_pen = interface_penalty(face_frame, face_interface_axis)
    unary = cost + penalty * iface_pen
    nb = part_neighbours(topology, face_part)
    if colour is None:
        colour = face_colouring(nb)
    angle0 = judge.angle(labels)
    angle_cap = angle0 + max_angle_increase

    def smoothed(cand):
        if not smooth:
            return cand, judge.validity(cand)
        v_c = judge.validity(cand)
        s = _smooth_boundaries(cand, _boundary_faces(topology, face_part, cand), unary, nb,
                               colour, lam, penalty)
        v_s = judge.validity(s)
        return (s, v_s) if v_s.n_invalid <= v_c.n_invalid else (cand, v_c)

    def smoothed_local(cand, n_cand, lay):
        """Smooth ``cand`` near its changes; returns (labels, invalid count) of the better."""
        if not smooth:
            return cand, n_cand
        faces, _ = judge.zone(labels, lay, cand)
        active = np.zeros(m, dtype=bool)
        active[faces] = True
        s = _smooth_boundaries(cand, active & _boundary_faces(topology, face_part, cand), unary,
                               nb, colour, lam, penalty)
        n_s = val.n_invalid + judge.delta(labels, val, s)[0]
        return (s, n_s) if n_s <= n_cand else (cand, n_cand)

    def score_candidates(cands, best):
        """Best of ``best`` and the named candidates ``cands`` for an invalid chart of ``labels``
        (judged as ``val``): (fewest invalid items, smallest mean angle) within the angle cap;
        candidates that leave opposite-label boundaries get the strip insertion first."""
        nonlocal trials
        for name, cand in cands:
            if np.array_equal(cand, labels) or judge.angle(cand) > angle_cap:
                continue
            trials += 1
            d, opp = judge.delta(labels, val, cand)
            n_c = val.n_invalid + d
            if opp:
                v_c = judge.validity(cand)
                for _ in range(2):
                    if not (v_c.boundary_reason == 1).any():
                        break
                    cand, _n = _fix_opposite(F, topology, v_c, cand, cost)
                    v_c = judge.validity(cand)
                    name += "+split_opposite"
                if judge.angle(cand) > angle_cap:
                    continue
                n_c = v_c.n_invalid
            score = (n_c, judge.angle(cand))
            if best is None or score < best[0]:
                best = (score, name, cand)
        return best

    before = judge.validity(labels)
    val = before
    ops = []
    gave_up = {}
    seen = {hash(labels.tobytes())}
    stopped = "round_cap"
    rounds = 0
    n_sideways = 0
    trials = 0
    for rounds in range(1, max_rounds + 1):
        if val.is_valid:
            stopped = "valid"
            rounds -= 1
            break
        accepted = None
        sideways = None
        if (val.boundary_reason == 1).any():
            lay = val.layout
            b = int(np.flatnonzero(val.boundary_reason == 1)[0])
            strip, count = _fix_opposite(F, topology, val, labels, cost)
            cands = [("split_opposite_boundaries", strip)]
            for c in lay.boundary_charts[b].tolist():
                nbrs = lay.chart_neighbours[c].indices
                nbrs = nbrs[lay.chart_part[nbrs] == lay.chart_part[c]]
                for lab in np.unique(lay.chart_label[nbrs]).tolist():
                    cand = labels.copy()
                    cand[lay.face_chart == c] = lab
                    cands.append((f"merge_opposite_chart_into_{lab}", cand))
            best = None
            for name, cand in cands:
                if judge.angle(cand) > angle_cap and name != cands[0][0]:
                    continue
                score = (val.n_invalid + judge.delta(labels, val, cand)[0], judge.angle(cand))
                if best is None or score < best[0]:
                    best = (score, name, cand)
            s_cand, n_s = smoothed_local(best[2], best[0][0], lay)
            best = ((n_s, judge.angle(s_cand)), best[1], s_cand)
            if best[0][0] >= val.n_invalid:
                best = (None, cands[0][0], strip)
            if hash(best[2].tobytes()) not in seen:
                accepted = (best[1], count if best[1] == cands[0][0] else 1, best[2],
                            judge.validity(best[2]))
        if accepted is None and (val.boundary_reason == 2).any():
            new, count = _fix_interface(F, topology, val, labels, cost, face_part, face_frame,
                                        iface_pen, judge.edge_ix)
            v_new = judge.validity(new)
            if v_new.n_invalid < val.n_invalid and hash(new.tobytes()) not in seen:
                accepted = ("relabel_interface_parallel", count, new, v_new)
        if accepted is None and val.invalid_chart.any():
            lay = val.layout
            small = val.invalid_chart & (lay.chart_size <= small_chart)
            if small.any():
                new, count = _merge_charts(val, labels, cost, small)
                new, v_new = smoothed(new)
                if v_new.n_invalid < val.n_invalid:
                    accepted = ("merge_small_charts", count, new, v_new)
            if accepted is None:
                bad = np.flatnonzero(val.invalid_chart)
                for c in bad[np.lexsort((bad, lay.chart_size[bad]))].tolist():
                    key = (int(lay.chart_first_face[c]), int(lay.chart_label[c]))
                    if key in gave_up or trials >= max_trials:
                        continue
                    best = score_candidates(
                        _chart_candidates(F, face_part, val, labels, c, cost, unary, nb, colour,
                                          penalty, (1.0, 2.0, 4.0, 8.0)), None)
                    if best is None or best[0][0] >= val.n_invalid:
                        best = score_candidates(_joint_merges(val.layout, labels, c, small_chart),
                                                best)
                    if best is not None:
                        s_cand, n_s = smoothed_local(best[2], best[0][0], lay)
                        best = ((n_s, judge.angle(s_cand)), best[1], s_cand)
                    if best is not None and best[0][0] < val.n_invalid:
                        accepted = (f"chart_{best[1]}", 1, best[2], judge.validity(best[2]))
                        break
                    if (best is not None and best[0][0] == val.n_invalid
                            and hash(best[2].tobytes()) not in seen):
                        sideways = sideways or (f"chart_{best[1]}_sideways", 1, best[2])
                    gave_up[key] = {"face": key[0], "label": key[1],
                                    "faces": int(lay.chart_size[c])}
                if accepted is None and sideways is not None and n_sideways < max_sideways:
                    accepted = sideways + (judge.validity(sideways[2]),)
                    gave_up.clear()
        if accepted is None and len(val.invalid_corners):
            corners, axes = _one_axis_corners(topology, val)
            if len(corners):
                new, count = _fix_one_axis_corners(F, topology, labels, face_part, cost, corners,
                                                   axes)
                v_new = judge.validity(new)
                if (v_new.n_invalid < val.n_invalid and judge.angle(new) <= angle_cap
                        and hash(new.tobytes()) not in seen):
                    accepted = ("insert_chart_at_one_axis_corners", count, new, v_new)
        if accepted is None and len(val.invalid_corners):
            new, count = _fix_corners(F, topology, val, labels, face_part)
            if hash(new.tobytes()) not in seen:
                accepted = ("relabel_corner_faces", count, new, judge.validity(new))
        if accepted is None or np.array_equal(accepted[2], labels):
            stopped = "stuck"
            break
        op, count, labels, val = accepted
        n_sideways = n_sideways + 1 if op.endswith("_sideways") else 0
        seen.add(hash(labels.tobytes()))
        ops.append({"round": rounds, "operator": op, "items": int(count),
                    "invalid_after": int(val.n_invalid)})
    else:
        if val.is_valid:
            stopped = "valid"
    final = judge.validity(labels)
    r = final.report
    unfixed = {k: r[k] for k in ("invalid_charts", "invalid_boundaries", "invalid_corners")
               if r[k]["count"]}
    report = {"rounds": int(rounds), "valid": bool(r["valid"]), "stopped": stopped,
              "operations": ops, "before": before.report, "after": r,
              "angle_before": angle0, "angle_after": judge.angle(labels),
              "gave_up": list(gave_up.values()), "unfixed": unfixed}
    return labels.astype(np.int32), report

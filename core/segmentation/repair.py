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

The loop is greedy, so it can stop where every candidate adds invalid items although one of them
is a step away from a labeling the operators finish (a merge that leaves a neighbour with three
boundaries, say). With ``escapes`` a stuck repair restarts from the best candidates of its
smallest invalid charts, growth around each single corner included, and keeps a restart that
ends with fewer invalid items (:func:`repair_labeling`, Notes).

The operators and the candidate trials are :mod:`core.segmentation.repair_operators` (each returns
a typed ``Relabel`` or ``Trial``); :class:`RepairRun` holds one repair's state and tries them in
this order, a round's accepted change being a :class:`Step`. Candidates are scored on the submesh
around the faces they change (exact; see :func:`core.segmentation.validity.local_invalid_count`);
only accepted states are judged whole.
Per-chart trials are capped (``max_trials``) and so are consecutive sideways moves
(``max_sideways``), so the work stays bounded on meshes with many invalid charts.
"""
from dataclasses import dataclass

import numpy as np

from core.errors import ParameterError
from core.geometry import face_areas
from core.segmentation.charts import build_topology
from core.segmentation.labeling import (LAMBDA, PENALTY, check_frames, face_colouring,
                                        face_normals, interface_penalty, label_cost,
                                        part_neighbours)
from core.segmentation.parts import face_interface_axes, interfaces
from core.segmentation.repair_operators import (Trial, boundary_faces, chart_candidates,
                                                corner_growths, faces_at_vertices,
                                                insert_one_axis_charts, joint_merges,
                                                merge_charts, one_axis_corners,
                                                relabel_corner_faces, relabel_interface_parallel,
                                                smooth_boundaries, split_opposite_boundaries)
from core.segmentation.validity import (check_validity, counts_near, edge_interface_axes,
                                        local_counts, local_invalid_count, with_turning_points)
from core.types import TriMesh

ESCAPE_CHARTS = 2
"""Invalid charts (the smallest) whose candidates a stuck repair's escape tries."""
ESCAPE_PER_CHART = 2
"""Best candidates per chart an escape tries."""


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
        charts[lay.face_chart[faces_at_vertices(F, vmask)]] = True
        vz = np.zeros_like(vmask)
        vz[F[charts[lay.face_chart]]] = True
        return np.flatnonzero(faces_at_vertices(F, vz))

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


@dataclass(frozen=True)
class Candidate:
    """A judged candidate labeling.

    name : str, the operator or trial that made it (the report's ``operator`` names it).
    labels : (m,) int64 labels 0..5.
    invalid : int, its invalid items (exact, from the judgement near its changes).
    angle : float, its area-weighted mean angle in degrees (:meth:`CandidateJudge.angle`).
    """

    name: str
    labels: np.ndarray
    invalid: int
    angle: float

    @property
    def score(self):
        """(invalid items, mean angle): the smaller the better."""
        return (self.invalid, self.angle)


@dataclass(frozen=True)
class Step:
    """The change a repair round accepts.

    operator : str, the report's name of what it did; items : int, the items it worked on.
    labels : (m,) int64 the new labels; validity : Validity of ``labels`` (whole mesh).
    """

    operator: str
    items: int
    labels: np.ndarray
    validity: object


class RepairRun:
    """One repair of a labeling: the current labels, their judgement and the bookkeeping.

    :meth:`step` tries the operators of the module docstring in order (one kind per round) and
    returns the first change it accepts; :meth:`accept` makes it the current labeling.

    Parameters
    ----------
    F : (m, 3) int64; face_part : (m,) int64; topology : MeshTopology.
    judge : CandidateJudge of the mesh, parts and frames.
    labels : (m,) int64 labels 0..5 to repair.
    iface_pen : (m, 6) float64 Eq. 3 interface penalty of each label.
    nb : (m, 3) int64 face neighbours within the part (-1: none); colour : (m,) int64.
    lam, penalty : float, Eq. 3 parameters of the smoothing and re-segmentation.
    smooth : bool, smooth the boundaries after merges.
    angle_cap : float, degrees: no chart operation may raise the mean angle above it.
    small_chart, max_trials, max_sideways : int, see :func:`repair_labeling`.
    """

    def __init__(self, F, face_part, topology, judge, labels, iface_pen, nb, colour, lam,
                 penalty, smooth, angle_cap, small_chart, max_trials, max_sideways):
        self.F, self.face_part, self.topology, self.judge = F, face_part, topology, judge
        self.iface_pen, self.unary = iface_pen, judge.cost + penalty * iface_pen
        self.nb, self.colour, self.lam, self.penalty = nb, colour, lam, penalty
        self.smooth, self.angle_cap = smooth, angle_cap
        self.small_chart, self.max_trials, self.max_sideways = small_chart, max_trials, max_sideways
        self.labels = labels
        self.val = judge.validity(labels)
        self.seen = {hash(labels.tobytes())}
        self.gave_up = {}  # (first face, label) of a chart no trial improved -> report entry
        self.trials = 0
        self.n_sideways = 0

    def step(self):
        """The first change an operator offers and the rules accept, or None (stuck)."""
        for operator in (self.opposite_step, self.interface_step, self.chart_step,
                         self.one_axis_corner_step, self.corner_step):
            found = operator()
            if found is not None:
                return found
        return None

    def accept(self, step):
        """Make ``step`` (a Step) the current labeling."""
        self.n_sideways = self.n_sideways + 1 if step.operator.endswith("_sideways") else 0
        self.labels, self.val = step.labels, step.validity
        self.seen.add(hash(step.labels.tobytes()))

    def is_new(self, labels):
        """Whether ``labels`` is a state this repair has not been in."""
        return hash(labels.tobytes()) not in self.seen

    def _smooth(self, labels, active):
        return smooth_boundaries(labels, active, self.unary, self.nb, self.colour, self.lam,
                                 self.penalty)

    def smoothed(self, operator, relabel):
        """Step of the Relabel ``relabel``, boundary-smoothed where that leaves no more invalid
        items."""
        v_c = self.judge.validity(relabel.labels)
        if not self.smooth:
            return Step(operator, relabel.items, relabel.labels, v_c)
        s = self._smooth(relabel.labels, boundary_faces(self.topology, self.face_part,
                                                         relabel.labels))
        v_s = self.judge.validity(s)
        if v_s.n_invalid <= v_c.n_invalid:
            return Step(operator, relabel.items, s, v_s)
        return Step(operator, relabel.items, relabel.labels, v_c)

    def smoothed_local(self, cand, lay):
        """Candidate ``cand``, smoothed near its changes where that leaves no more invalid
        items (``lay``: the current labeling's layout)."""
        if not self.smooth:
            return cand
        faces, _ = self.judge.zone(self.labels, lay, cand.labels)
        active = np.zeros(len(self.F), dtype=bool)
        active[faces] = True
        s = self._smooth(cand.labels, active & boundary_faces(self.topology, self.face_part,
                                                              cand.labels))
        n_s = self.val.n_invalid + self.judge.delta(self.labels, self.val, s)[0]
        if n_s <= cand.invalid:
            return Candidate(cand.name, s, n_s, self.judge.angle(s))
        return cand

    def scored(self, trials):
        """The Trials ``trials`` for an invalid chart of the current labeling as Candidates
        (invalid items, mean angle), those within the angle cap that change the labeling;
        trials that leave opposite-label boundaries get the strip insertion first."""
        judge, labels, val = self.judge, self.labels, self.val
        for trial in trials:
            name, cand = trial.name, trial.labels
            if np.array_equal(cand, labels) or judge.angle(cand) > self.angle_cap:
                continue
            self.trials += 1
            d, opp = judge.delta(labels, val, cand)
            n_c = val.n_invalid + d
            if opp:
                v_c = judge.validity(cand)
                for _ in range(2):
                    if not (v_c.boundary_reason == 1).any():
                        break
                    cand = split_opposite_boundaries(self.F, self.topology, v_c, cand,
                                                     judge.cost).labels
                    v_c = judge.validity(cand)
                    name += "+split_opposite"
                if judge.angle(cand) > self.angle_cap:
                    continue
                n_c = v_c.n_invalid
            yield Candidate(name, cand, n_c, judge.angle(cand))

    def best_of(self, trials, best):
        """Best of ``best`` (a Candidate or None) and the :meth:`scored` Trials ``trials``:
        fewest invalid items, then smallest mean angle."""
        for scored in self.scored(trials):
            if best is None or scored.score < best.score:
                best = scored
        return best

    def own_trials(self, c):
        """The :func:`chart_candidates` of invalid chart ``c`` of the current labeling."""
        return chart_candidates(self.F, self.face_part, self.val, self.labels, c,
                                self.judge.cost, self.unary, self.nb, self.colour, self.penalty,
                                (1.0, 2.0, 4.0, 8.0))

    def joint_trials(self, c):
        """The :func:`joint_merges` of invalid chart ``c`` with its small neighbours."""
        lay = self.val.layout
        return joint_merges(lay, self.labels, c, lay.chart_size <= self.small_chart)

    def escapes(self, charts, per_chart):
        """Candidates that leave a stuck labeling, uphill if need be: for each of the
        ``charts`` smallest invalid charts, its ``per_chart`` best :meth:`scored` trials (those
        of a chart step and its :func:`corner_growths`, one per corner, which only a stuck
        repair pays for), best first over all."""
        lay = self.val.layout
        bad = np.flatnonzero(self.val.invalid_chart)
        found = []
        for c in bad[np.lexsort((bad, lay.chart_size[bad]))][:charts].tolist():
            trials = self.own_trials(c) + self.joint_trials(c) + corner_growths(
                self.F, self.face_part, lay, self.labels, c)
            ranked = sorted(self.scored(trials), key=lambda cand: cand.score)
            found += [cand for cand in ranked if self.is_new(cand.labels)][:per_chart]
        return sorted(found, key=lambda cand: cand.score)

    def opposite_step(self):
        """Operator 1: the strip insertion or a merge of a chart of the first opposite-label
        boundary, whichever leaves the fewest invalid items (the strip when none helps)."""
        judge, labels, val = self.judge, self.labels, self.val
        if not (val.boundary_reason == 1).any():
            return None
        lay = val.layout
        b = int(np.flatnonzero(val.boundary_reason == 1)[0])
        strip = split_opposite_boundaries(self.F, self.topology, val, labels, judge.cost)
        trials = [Trial("split_opposite_boundaries", strip.labels)]
        for c in lay.boundary_charts[b].tolist():
            nbrs = lay.chart_neighbours[c].indices
            nbrs = nbrs[lay.chart_part[nbrs] == lay.chart_part[c]]
            for lab in np.unique(lay.chart_label[nbrs]).tolist():
                cand = labels.copy()
                cand[lay.face_chart == c] = lab
                trials.append(Trial(f"merge_opposite_chart_into_{lab}", cand))
        best = None
        for k, trial in enumerate(trials):
            if judge.angle(trial.labels) > self.angle_cap and k > 0:
                continue
            cand = Candidate(trial.name, trial.labels,
                             val.n_invalid + judge.delta(labels, val, trial.labels)[0],
                             judge.angle(trial.labels))
            if best is None or cand.score < best.score:
                best = cand
        best = self.smoothed_local(best, lay)
        if best.invalid >= val.n_invalid:
            best = Candidate(trials[0].name, strip.labels, best.invalid, best.angle)
        if not self.is_new(best.labels):
            return None
        items = strip.items if best.name == trials[0].name else 1
        return Step(best.name, items, best.labels, judge.validity(best.labels))

    def interface_step(self):
        """Operator 2, kept when it lowers the invalid count."""
        val, judge = self.val, self.judge
        if not (val.boundary_reason == 2).any():
            return None
        new = relabel_interface_parallel(self.F, self.topology, val, self.labels, judge.cost,
                                         self.face_part, judge.face_frame, self.iface_pen,
                                         judge.edge_ix)
        v_new = judge.validity(new.labels)
        if v_new.n_invalid < val.n_invalid and self.is_new(new.labels):
            return Step("relabel_interface_parallel", new.items, new.labels, v_new)
        return None

    def chart_step(self):
        """Operator 3: the small invalid charts merged in a batch, else per chart (smallest
        first) the best trial that lowers the invalid count, else a sideways move."""
        judge, labels, val = self.judge, self.labels, self.val
        if not val.invalid_chart.any():
            return None
        lay = val.layout
        small = val.invalid_chart & (lay.chart_size <= self.small_chart)
        if small.any():
            step = self.smoothed("merge_small_charts", merge_charts(val, labels, judge.cost,
                                                                    small))
            if step.validity.n_invalid < val.n_invalid:
                return step
        sideways = None
        bad = np.flatnonzero(val.invalid_chart)
        for c in bad[np.lexsort((bad, lay.chart_size[bad]))].tolist():
            key = (int(lay.chart_first_face[c]), int(lay.chart_label[c]))
            if key in self.gave_up or self.trials >= self.max_trials:
                continue
            best = self.best_of(self.own_trials(c), None)
            if best is None or best.invalid >= val.n_invalid:
                best = self.best_of(self.joint_trials(c), best)
            if best is not None:
                best = self.smoothed_local(best, lay)
                if best.invalid < val.n_invalid:
                    return Step(f"chart_{best.name}", 1, best.labels,
                                judge.validity(best.labels))
                if best.invalid == val.n_invalid and sideways is None and self.is_new(
                        best.labels):
                    sideways = Candidate(f"chart_{best.name}_sideways", best.labels,
                                         best.invalid, best.angle)
            self.gave_up[key] = {"face": key[0], "label": key[1],
                                 "faces": int(lay.chart_size[c])}
        if sideways is not None and self.n_sideways < self.max_sideways:
            step = Step(sideways.name, 1, sideways.labels, judge.validity(sideways.labels))
            self.gave_up.clear()
            return step
        return None

    def one_axis_corner_step(self):
        """Operator 4, kept when it lowers the invalid count within the angle cap."""
        val, judge = self.val, self.judge
        if not len(val.invalid_corners):
            return None
        corners = one_axis_corners(self.topology, val)
        if not len(corners.vertices):
            return None
        new = insert_one_axis_charts(self.F, self.topology, self.labels, self.face_part,
                                     judge.cost, corners)
        v_new = judge.validity(new.labels)
        if (v_new.n_invalid < val.n_invalid and judge.angle(new.labels) <= self.angle_cap
                and self.is_new(new.labels)):
            return Step("insert_chart_at_one_axis_corners", new.items, new.labels, v_new)
        return None

    def corner_step(self):
        """Operator 5 (the last resort: kept whenever it makes a new state)."""
        if not len(self.val.invalid_corners):
            return None
        new = relabel_corner_faces(self.F, self.topology, self.val, self.labels, self.face_part)
        if not self.is_new(new.labels):
            return None
        return Step("relabel_corner_faces", new.items, new.labels,
                    self.judge.validity(new.labels))


def repair_labeling(V, F, face_part, face_label, face_frame, face_interface_axis=None,
                    max_rounds=60, smooth=True, max_angle_increase=4.0, small_chart=None,
                    lam=LAMBDA, penalty=PENALTY, topology=None, max_trials=None,
                    max_sideways=4, colour=None, judge=None, escapes=0):
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
    escapes : int >= 0, uphill restarts a stuck repair may try (see Notes).

    Returns
    -------
    labels : (m,) int32 repaired labels.
    report : dict with ``rounds``, ``valid``, ``stopped`` (``valid``, ``stuck`` or
        ``round_cap``), ``operations`` (per-round operator and item count), ``before`` and
        ``after`` (the validity reports, without turning points: the monotonicity pass counts
        them), ``angle_before`` / ``angle_after`` (area-weighted mean degrees), ``gave_up``
        (charts no candidate improved: example face, label, faces), ``escapes`` (uphill
        restarts tried) and ``unfixed`` (the remaining invalid items with examples, empty when
        valid).

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

    A repair is greedy: it stops ("stuck") where every candidate adds invalid items, although
    a merge that breaks a neighbouring chart is often one step from a labeling the operators
    can finish. With ``escapes``, a stuck repair takes the best candidates of its smallest
    invalid charts (:meth:`RepairRun.escapes`, best first) one at a time, repairs from each as
    from a new input (same angle cap, fresh trial caps) and keeps the first that ends with fewer
    invalid items than the stuck labeling (then, if stuck again, escapes again), at most
    ``escapes`` restarts in all.
    """
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    if int(max_rounds) < 0 or int(escapes) < 0:
        raise ParameterError(f"max_rounds and escapes must be >= 0, got {max_rounds}, {escapes}")
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
    if face_interface_axis is None and face_part.max(initial=0) > 0:
        itfs = interfaces(TriMesh(V, F), face_part)
        face_interface_axis = face_interface_axes(F, face_part, itfs, V)[1]
    iface_pen = interface_penalty(judge.face_frame, face_interface_axis)
    nb = part_neighbours(topology, face_part)
    if colour is None:
        colour = face_colouring(nb)
    angle0 = judge.angle(labels)

    def new_run(start):
        return RepairRun(F, face_part, topology, judge, start, iface_pen, nb, colour, lam,
                         penalty, smooth, angle0 + max_angle_increase, small_chart, max_trials,
                         max_sideways)

    run = new_run(labels)
    before = run.val
    ops = []
    stopped, rounds = _descend(run, max_rounds, ops)
    tried = 0
    while stopped == "stuck" and tried < escapes:
        for cand in run.escapes(ESCAPE_CHARTS, ESCAPE_PER_CHART)[:escapes - tried]:
            tried += 1
            sub = new_run(cand.labels)
            sub_ops = [{"round": 0, "operator": f"escape_{cand.name}", "items": 1,
                        "invalid_after": int(sub.val.n_invalid)}]
            sub_stopped, sub_rounds = _descend(sub, max_rounds, sub_ops)
            if sub.val.n_invalid < run.val.n_invalid:
                run, stopped = sub, sub_stopped
                rounds += sub_rounds
                ops += sub_ops
                break
        else:
            break
    labels = run.labels
    final = judge.validity(labels)
    r = final.report
    unfixed = {k: r[k] for k in ("invalid_charts", "invalid_boundaries", "invalid_corners")
               if r[k]["count"]}
    for k, op in enumerate(ops):
        op["round"] = k + 1
    report = {"rounds": int(rounds), "valid": bool(r["valid"]), "stopped": stopped,
              "operations": ops, "escapes": tried, "before": before.report, "after": r,
              "angle_before": angle0, "angle_after": judge.angle(labels),
              "gave_up": list(run.gave_up.values()), "unfixed": unfixed}
    return labels.astype(np.int32), report


def _descend(run, max_rounds, ops):
    """Apply ``run``'s steps (:meth:`RepairRun.step`) until its labeling is valid, no step is
    left or ``max_rounds`` rounds, appending each to ``ops`` (report entries).

    Returns
    -------
    stopped : ``valid``, ``stuck`` or ``round_cap``; rounds : int, the rounds used.
    """
    for rounds in range(1, max_rounds + 1):
        if run.val.is_valid:
            return "valid", rounds - 1
        step = run.step()
        if step is None or np.array_equal(step.labels, run.labels):
            return "stuck", rounds
        run.accept(step)
        ops.append({"round": 0, "operator": step.operator, "items": int(step.items),
                    "invalid_after": int(step.validity.n_invalid)})
    return ("valid" if run.val.is_valid else "round_cap"), max_rounds

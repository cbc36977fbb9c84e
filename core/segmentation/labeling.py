# SPDX-License-Identifier: LGPL-2.1-or-later
"""HBECVT polycube labeling (paper Sect. 2.2, Eqs. 2-3).

For face ``i`` and label ``l`` (0..5 = +X, -X, +Y, -Y, +Z, -Z of the face's frame, direction
``c_l``) Eq. 3 reads

    d(i, l)^2 = ||n_i - c_l||^2 + lambda * sum_{j in N(i): l_j != l} e_ij
                + p * (#{j in N(i): l_j = opposite(l)} + [i next to an interface and c_l
                parallel to the interface x-axis])

with ``lambda = 0.5``, ``p = 1e5`` and ``N(i)`` the edge-adjacent faces of the same part (labels of
other parts live in other frames). The paper counts the neighbours of another label
(``e_ij = 1``); here each counts with the length of the edge between ``i`` and ``j`` over the mean
edge length of the mesh (:func:`edge_weights`), so a chart boundary costs its length, not the
number of triangle edges it happens to follow: on a mesh of equal triangles ``e_ij`` is about 1
and Eq. 3 is the paper's, so lambda keeps its meaning. The data term stays per face, as in the
paper: the working surface of a fine target has triangles of about one size
(:mod:`core.proxy`), where an area weight would be about 1 too, and on a coarse target a face's
label is its own decision whatever its size. The penalty terms are hard constraints and stay
counts.

Eq. 2's harmonic mean ``L / sum_l d^-1`` is the energy the method is named after; the update
gives each face the label of smallest ``d``, which is the same as smallest ``d^2``. Starting
from the nearest-direction labels, sweeps update all faces until no label changes or the sweep
cap. A sweep visits the colour classes of a deterministic greedy colouring of the face adjacency
graph one after the other (at most four classes on a triangle mesh); faces of one class have no
common edge, so updating a class at once is exact coordinate descent on
``sum_i ||n_i - c_{l_i}||^2 + lambda * sum_{different-label edges} e_ij
+ p * #opposite-label edges`` and cannot oscillate (updating all faces at once can flip pairs of
neighbours forever). Ties keep the current label.

With ``p = 1e5`` a face with an opposite-labelled neighbour effectively cannot take that label
(unless every label is blocked), so the sweeps never create +X/-X neighbours; labels that already
touch an opposite label (from the nearest-direction start) are pushed to a perpendicular label.
"""
import numpy as np

from core.errors import InvalidMeshError, ParameterError
from core.geometry import face_cross
from core.params import ReconstructionParams
from core.segmentation.charts import OPPOSITE, build_topology
from core.tolerances import ZERO_AREA

LAMBDA = ReconstructionParams.lam
PENALTY = ReconstructionParams.penalty
MAX_SWEEPS = ReconstructionParams.max_sweeps


def face_normals(V, F):
    """(m, 3) float64 unit normals; raises ``InvalidMeshError`` on zero-area faces.

    A face counts as zero-area when twice its area is at most ``core.tolerances.ZERO_AREA``
    times the squared bounding-box diagonal (the intake's test).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    cr = face_cross(V, F)
    norm = np.linalg.norm(cr, axis=1)
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) if len(V) else 0.0
    bad = np.flatnonzero(~(norm > ZERO_AREA * diag * diag))
    if len(bad):
        raise InvalidMeshError(
            f"F has {len(bad)} zero-area faces (e.g. face {int(bad[0])}); labeling needs normals",
            "degenerate_faces", len(bad), bad[:5].tolist())
    return cr / norm[:, None]


def label_vectors(face_frame):
    """(m, 6, 3) float64 directions +x, -x, +y, -y, +z, -z of each face's frame."""
    face_frame = np.asarray(face_frame, dtype=np.float64)
    return np.stack([face_frame[:, 0], -face_frame[:, 0], face_frame[:, 1], -face_frame[:, 1],
                     face_frame[:, 2], -face_frame[:, 2]], axis=1)


def label_directions(face_label, face_frame):
    """(m, 3) float64 unit world direction of each face's label."""
    face_label = np.asarray(face_label, dtype=np.int64)
    sign = np.where(face_label % 2 == 0, 1.0, -1.0)
    return np.asarray(face_frame)[np.arange(len(face_label)), face_label // 2] * sign[:, None]


def label_dots(normals, face_frame):
    """(m, 6) float64 dot product of each unit normal with the six label directions of its frame
    (the rows of :func:`label_vectors`), from the three frame axes."""
    d = np.einsum("fij,fj->fi", np.asarray(face_frame, dtype=np.float64), normals)
    return np.stack([d[:, 0], -d[:, 0], d[:, 1], -d[:, 1], d[:, 2], -d[:, 2]], axis=1)


def nearest_direction_labels(normals, face_frame):
    """(m,) int32 label whose direction is nearest to each normal (no smoothing)."""
    return np.argmax(label_dots(normals, face_frame), axis=1).astype(np.int32)


def mean_label_angle(normals, face_label, face_frame, weights=None):
    """Mean angle in degrees between face normals and their label directions.

    ``weights`` : optional (m,) float weights (e.g. face areas); plain mean when omitted.
    """
    d = label_directions(face_label, face_frame)
    ang = np.degrees(np.arccos(np.clip((d * normals).sum(axis=1), -1.0, 1.0)))
    return float(np.average(ang, weights=weights))


def check_frames(face_frame, m, name="face_frame"):
    """Validate per-face frames: shape (m, 3, 3), finite, orthonormal rows (tolerance 1e-6)."""
    face_frame = np.asarray(face_frame, dtype=np.float64)
    if face_frame.shape != (m, 3, 3):
        raise ParameterError(f"{name} must have shape ({m}, 3, 3), got {face_frame.shape}")
    # the six distinct entries of each frame's Gram matrix minus the identity
    err = np.zeros(m)
    for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        dot = np.einsum("fk,fk->f", face_frame[:, i], face_frame[:, j])
        err = np.maximum(err, np.abs(dot - (i == j)))
    bad = np.flatnonzero(~(err < 1e-6))
    if len(bad):
        raise ParameterError(f"{name} has {len(bad)} frames that are not orthonormal or not "
                             f"finite (e.g. face {int(bad[0])})")
    return face_frame


def face_colouring(neighbours):
    """Deterministic greedy colouring of the face adjacency graph (vectorised rounds).

    Parameters
    ----------
    neighbours : (m, k) int64 neighbouring faces, ``-1`` where none.

    Returns
    -------
    (m,) int64 colour of each face; neighbouring faces get different colours.

    Notes
    -----
    Jones-Plassmann rounds: a face whose fixed pseudo-random priority (a multiplicative hash of its
    index) beats all its uncoloured neighbours takes the smallest colour unused around it.
    """
    m, k = neighbours.shape
    idx = np.arange(m, dtype=np.uint64)
    prio = ((idx * np.uint64(2654435761)) % np.uint64(4294967291)).astype(np.int64) * m + np.arange(m)
    colour = np.full(m, -1, dtype=np.int64)
    has = neighbours >= 0
    nb = np.where(has, neighbours, 0)
    todo = np.arange(m)
    while len(todo):
        # a face is picked when its priority beats every uncoloured neighbour's
        nb_t, has_t = nb[todo], has[todo]
        nb_prio = np.where(has_t & (colour[nb_t] < 0), prio[nb_t], -1)
        pick = prio[todo] > nb_prio.max(axis=1)
        faces = todo[pick]
        nb_col = np.where(has_t[pick], colour[nb_t[pick]], -1)  # uncoloured neighbours are -1
        c = np.zeros(len(faces), dtype=np.int64)
        for _ in range(k + 1):
            c += (nb_col == c[:, None]).any(axis=1)
        colour[faces] = c
        todo = todo[~pick]
    return colour


def part_neighbours(topology, face_part):
    """(m, 3) int64 edge neighbours restricted to the face's own part (``-1`` otherwise)."""
    nb = topology.neighbours
    own = np.asarray(face_part)[:, None]
    ok = nb >= 0
    same = ok & (np.asarray(face_part)[np.where(ok, nb, 0)] == own)
    return np.where(same, nb, -1)


def interface_penalty(face_frame, face_interface_axis):
    """(m, 6) float64 Eq. 3 term 4 indicator: 1 for the two labels of the frame axis nearest to the
    interface x-axis on faces next to an interface (finite rows of ``face_interface_axis``)."""
    m = len(face_frame)
    pen = np.zeros((m, 6))
    if face_interface_axis is None:
        return pen
    ia = np.asarray(face_interface_axis, dtype=np.float64)
    if ia.shape != (m, 3):
        raise ParameterError(f"face_interface_axis must have shape ({m}, 3), got {ia.shape}")
    rows = np.flatnonzero(np.isfinite(ia).all(axis=1))
    if len(rows):
        local = np.abs(np.einsum("fij,fj->fi", face_frame[rows], ia[rows]))
        k = np.argmax(local, axis=1)
        pen[rows, 2 * k] = 1.0
        pen[rows, 2 * k + 1] = 1.0
    return pen


def edge_weights(V, topology):
    """(m, 3) float64 Eq. 3 weight ``e_ij`` of each face's neighbour across its edge ``k``
    (``topology.neighbours[:, k]``): the edge's length over the mean edge length of the mesh.

    Parameters
    ----------
    V : (n, 3) float64 vertices.
    topology : MeshTopology (``edges``, ``face_edges``).
    """
    V = np.asarray(V, dtype=np.float64)
    length = np.linalg.norm(V[topology.edges[:, 0]] - V[topology.edges[:, 1]], axis=1)
    return length[topology.face_edges] / length.mean()


def hbecvt_sweeps(unary, neighbours, labels, colour, lam=LAMBDA, penalty=PENALTY,
                  max_sweeps=MAX_SWEEPS, active=None, edge_weight=None):
    """Minimise Eq. 3 face by face with coloured sweeps (in place on a copy).

    Parameters
    ----------
    unary : (m, 6) float64 per-label cost without the neighbour terms (term 1 + p * term 4).
    neighbours : (m, k) int64 neighbours in the same part, ``-1`` where none.
    labels : (m,) int initial labels.
    colour : (m,) int64 colour classes of :func:`face_colouring`.
    lam, penalty : float, lambda and p of Eq. 3.
    max_sweeps : int, cap on full sweeps.
    active : (m,) bool, optional; only these faces may change.
    edge_weight : (m, k) float64, optional weight ``e_ij`` of each neighbour in the lambda
        term (:func:`edge_weights`); 1 for every neighbour when omitted.

    Returns
    -------
    labels : (m,) int32
    sweeps : int, sweeps run (the last one changed nothing unless the cap was hit)

    Notes
    -----
    A face is visited again only once a neighbour has moved since its last visit: with the same
    neighbour labels it would pick the label it holds (its label was the minimum, and the tie
    rule keeps it), so skipping it gives the same labels and sweep count as visiting every face.
    """
    labels = np.asarray(labels, dtype=np.int64).copy()
    has = neighbours >= 0
    nb = np.where(has, neighbours, 0)
    weight = has.astype(np.float64) if edge_weight is None else np.where(has, edge_weight, 0.0)
    deg = weight.sum(axis=1)
    classes = [np.flatnonzero((colour == c) & (True if active is None else active))
               for c in range(int(colour.max()) + 1)]
    # only faces with a neighbour that moved since their last visit can move (see Notes)
    stale = np.ones(len(labels), dtype=bool)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        changed = 0
        for members in classes:
            faces = members[stale[members]]
            if len(faces) == 0:
                continue
            stale[faces] = False
            nl, hf, wf = labels[nb[faces]], has[faces], weight[faces]
            rows = np.arange(len(faces))
            # per label: neighbours holding it (counted, for the penalty) and their weight
            cnt = np.zeros((len(faces), 6))
            same = np.zeros((len(faces), 6))
            for j in range(nb.shape[1]):
                cnt[rows, nl[:, j]] += hf[:, j]
                same[rows, nl[:, j]] += wf[:, j]
            d2 = (unary[faces] + lam * (deg[faces][:, None] - same)
                  + penalty * cnt[:, OPPOSITE])
            cur = labels[faces]
            d2[rows, cur] -= 1e-9
            new = np.argmin(d2, axis=1)
            moved = new != cur
            changed += int(moved.sum())
            labels[faces[moved]] = new[moved]
            stale[nb[faces[moved]][has[faces[moved]]]] = True
        if changed == 0:
            break
    return labels.astype(np.int32), sweeps


def hbecvt_labeling(V, F, face_part, face_frame, face_interface_axis=None, lam=LAMBDA,
                    penalty=PENALTY, max_sweeps=MAX_SWEEPS, topology=None, colour=None,
                    normals=None):
    """HBECVT labels of every face (Eqs. 2-3, the neighbours weighted by edge length as in
    the module docstring).

    Parameters
    ----------
    V : (n, 3) float64 vertices.
    F : (m, 3) int faces (closed, outward-oriented).
    face_part : (m,) int part of each face.
    face_frame : (m, 3, 3) float64 rows x, y, z of each face's frame (world coordinates).
    face_interface_axis : (m, 3) float64, optional; the interface x-axis for faces next to a part
        interface (a vertex on it, see :func:`core.segmentation.frames.face_interface_axes`), NaN
        rows elsewhere (Eq. 3 term 4).
    lam : float, lambda (default 0.5); penalty : float, p (default 1e5).
    max_sweeps : int, iteration cap.
    topology : MeshTopology, optional.
    colour : (m,) int64, optional :func:`face_colouring` of :func:`part_neighbours` (computed
        when omitted).
    normals : (m, 3) float64, optional :func:`face_normals` (computed when omitted).

    Returns
    -------
    labels : (m,) int32 in 0..5.
    info : dict with ``sweeps``, ``converged`` and ``changed_from_nearest`` (faces).

    Raises
    ------
    InvalidMeshError on zero-area faces; ParameterError on bad frames or parameters.
    """
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    if not lam >= 0 or not penalty >= 0 or int(max_sweeps) < 1:
        raise ParameterError(f"need lam >= 0, penalty >= 0, max_sweeps >= 1; got {lam}, "
                             f"{penalty}, {max_sweeps}")
    face_part = np.asarray(face_part, dtype=np.int64)
    if face_part.shape != (m,):
        raise ParameterError(f"face_part must have shape ({m},), got {face_part.shape}")
    face_frame = check_frames(face_frame, m)
    if normals is None:
        normals = face_normals(V, F)
    if topology is None:
        topology = build_topology(F, len(V))
    unary = label_cost(normals, face_frame) + penalty * interface_penalty(face_frame,
                                                                          face_interface_axis)
    nb = part_neighbours(topology, face_part)
    if colour is None:
        colour = face_colouring(nb)
    start = np.argmin(unary, axis=1)
    labels, sweeps = hbecvt_sweeps(unary, nb, start, colour, lam, penalty, max_sweeps,
                                   edge_weight=edge_weights(V, topology))
    info = {"sweeps": int(sweeps), "converged": bool(sweeps < max_sweeps),
            "changed_from_nearest": int((labels != start).sum())}
    return labels, info


def label_cost(normals, face_frame):
    """(m, 6) float64 Eq. 3 term 1, ``||n_i - c_l||^2 = 2 - 2 n_i . c_l``."""
    return 2.0 - 2.0 * label_dots(normals, face_frame)

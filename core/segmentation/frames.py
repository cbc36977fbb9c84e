# SPDX-License-Identifier: LGPL-2.1-or-later
"""Local coordinate frames of parts and interfaces, blended per face (paper Sect. 2.2, Eq. 1).

A frame is a (3, 3) float64 array whose rows are the local x, y, z axes in world
coordinates: orthonormal and right-handed (``det == +1``).

PCA (Eq. 1) gives the axes as eigenvectors of a covariance sorted from the smallest to
the largest eigenvalue. Sign convention (deterministic, independent of vertex order):
x and y are flipped so that their world component of largest magnitude is positive
(the first such component on ties); z = x cross y.

Two point sets are offered for parts:

- ``"area"`` (default): the exact area-weighted covariance of the surface (integral of
  ``p p^T`` over the triangles). It does not depend on how densely a region is meshed.
- ``"vertices"``: Eq. 1 literally, the covariance of the part's vertices.

Where PCA leaves a rotation free (two eigenvalues within ``degenerate_tol`` of each
other, e.g. a square bar or a cube), the free rotation is fixed by aligning the axes to
the face normals (closed-form minimum of the area-weighted cubic energy
``sum A (n.u)^2 (n.v)^2`` over the free angle); ``align_degenerate=False`` keeps plain PCA.
"""
from dataclasses import dataclass, replace
from itertools import permutations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from core.errors import ParameterError
from core.geometry import face_cross
from core.mesh_topology import edge_faces, unique_edges
from core.segmentation.parts import (face_interface_axes, interfaces as find_interfaces,
                                     validate_face_part)

DEFAULT_DEGENERATE_TOL = 0.1
FRAME_MODES = ("area", "vertices")
FRAME_CHOICES = ("energy", "pca")


def orient_frame(axes):
    """Sign convention for rows x, y of (3, 3) ``axes``; z = x cross y."""
    out = np.array(axes, dtype=np.float64)
    for k in (0, 1):
        a = out[k]
        mag = np.abs(a)
        if a[int(np.argmax(mag > mag.max() - 1e-12))] < 0:
            out[k] = -a
    x, y = out[0], out[1]
    z = np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])
    out[2] = z / np.sqrt(z @ z)
    return out


def frame_from_covariance(cov):
    """PCA frame of a (3, 3) symmetric covariance.

    Returns
    -------
    frame : (3, 3) float64, rows x, y, z = eigenvectors for eigenvalues sorted ascending,
        oriented by the module's sign convention (right-handed).
    eigenvalues : (3,) float64 ascending.
    """
    cov = np.asarray(cov, dtype=np.float64)
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    return orient_frame(vecs.T), vals


def pca_frame(points, weights=None):
    """PCA frame of a point set (Eq. 1).

    Parameters
    ----------
    points : (k, 3) float64, k >= 1.
    weights : (k,) float64 non-negative, optional; uniform (Eq. 1) when omitted.

    Returns
    -------
    (3, 3) float64, rows x, y, z (smallest to largest variance), right-handed.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ParameterError(f"points must be a non-empty (k, 3) array, got shape {points.shape}")
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(points),) or (w < 0).any() or w.sum() <= 0:
        raise ParameterError("weights must be (k,) non-negative with a positive sum")
    mean = (w[:, None] * points).sum(axis=0) / w.sum()
    d = points - mean
    cov = (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0) / w.sum()
    return frame_from_covariance(cov)[0]


# ----------------------------------------------------------------------------------------
# additive surface moments (used for frames of parts and of unions of parts)

@dataclass
class SurfaceMoments:
    """Additive moments of a set of triangles.

    area : float, total area.
    first : (3,) integral of p dA.
    second : (3, 3) integral of p p^T dA.
    normal4 : (3, 3, 3, 3) sum over faces of area * n (x) n (x) n (x) n (unit normals).
    """

    area: float
    first: np.ndarray
    second: np.ndarray
    normal4: np.ndarray

    def __add__(self, other):
        return SurfaceMoments(self.area + other.area, self.first + other.first,
                              self.second + other.second, self.normal4 + other.normal4)

    def covariance(self):
        """(3, 3) area-weighted covariance of the surface."""
        mean = self.first / self.area
        return self.second / self.area - np.outer(mean, mean)


def face_geometry(vertices, faces):
    """Per-face area (m,), unit normal (m, 3) and second moment (m, 3, 3) about the origin."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    cross = face_cross(vertices, faces)
    dbl = np.linalg.norm(cross, axis=1)
    area = 0.5 * dbl
    normal = cross / np.where(dbl > 0, dbl, 1.0)[:, None]
    s = tri.sum(axis=1)
    second = (area / 12.0)[:, None, None] * (np.einsum("fki,fkj->fij", tri, tri)
                                             + s[:, :, None] * s[:, None, :])
    return area, normal, second


def group_moments(vertices, faces, group, n_groups, chunk=20000):
    """List of :class:`SurfaceMoments`, one per group of faces.

    group : (m,) int64 in [0, n_groups).
    """
    faces = np.asarray(faces, dtype=np.int64)
    group = np.asarray(group, dtype=np.int64)
    area_sum = np.zeros(n_groups)
    first = np.zeros((n_groups, 3))
    second = np.zeros((n_groups, 9))
    normal4 = np.zeros((n_groups, 81))
    for start in range(0, len(faces), chunk):
        sl = slice(start, start + chunk)
        area, normal, sec = face_geometry(vertices, faces[sl])
        centroid = np.asarray(vertices, dtype=np.float64)[faces[sl]].mean(axis=1)
        g = group[sl]
        ind = sp.csr_matrix((np.ones(len(g)), (g, np.arange(len(g)))), shape=(n_groups, len(g)))
        area_sum += ind @ area
        first += ind @ (area[:, None] * centroid)
        second += ind @ sec.reshape(-1, 9)
        n2 = normal[:, :, None] * normal[:, None, :]
        n4 = (n2[:, :, :, None, None] * n2[:, None, None, :, :]).reshape(-1, 81)
        normal4 += ind @ (area[:, None] * n4)
    return [SurfaceMoments(area_sum[g], first[g], second[g].reshape(3, 3),
                           normal4[g].reshape(3, 3, 3, 3)) for g in range(n_groups)]


def cubic_energy(normal4, frame):
    """Area-weighted cubic misalignment ``sum A (1 - sum_k (n.a_k)^4) / 2`` of normals.

    Zero when every normal is along an axis of ``frame``; ``normal4`` is a
    (3, 3, 3, 3) normal moment (see :class:`SurfaceMoments`).
    """
    t = normal4.reshape(9, 9)
    area = t[np.ix_([0, 4, 8], [0, 4, 8])].sum()
    sq = (np.asarray(frame)[:, :, None] * np.asarray(frame)[:, None, :]).reshape(3, 9)
    fourth = ((sq @ t) * sq).sum()
    return 0.5 * (area - fourth)


def _quartic(normal4, a, b, c, d):
    """Contraction ``sum T_ijkl a_i b_j c_k d_l`` of a (3, 3, 3, 3) moment."""
    left = np.outer(a, b).ravel()
    right = np.outer(c, d).ravel()
    return float(left @ normal4.reshape(9, 9) @ right)


def align_about(frame, axis, normal4):
    """Rotate ``frame`` about its row ``axis`` to minimise the cubic energy (closed form)."""
    i, j = [k for k in range(3) if k != axis]
    y, z = frame[i], frame[j]

    def m(p):
        return _quartic(normal4, *([y] * p + [z] * (4 - p)))

    m40, m31, m22, m13, m04 = m(4), m(3), m(2), m(1), m(0)
    alpha2 = 0.25 * (m04 - 2.0 * m22 + m40)
    beta2 = m22
    alphabeta = 0.5 * (m13 - m31)
    rc, rs = 0.5 * (beta2 - alpha2), alphabeta
    scale = abs(m40) + abs(m04) + abs(m22) + 1e-300
    if np.hypot(rc, rs) < 1e-9 * scale:
        return frame
    theta = (np.arctan2(rs, rc) + np.pi) / 4.0
    c, s = np.cos(theta), np.sin(theta)
    out = frame.copy()
    out[i] = c * y + s * z
    out[j] = -s * y + c * z
    return out


def align_degenerate_axes(frame, eigenvalues, normal4, tol=DEFAULT_DEGENERATE_TOL):
    """Fix the rotation PCA leaves free using the face normals.

    Parameters
    ----------
    frame : (3, 3) PCA frame (rows x, y, z, eigenvalues ascending).
    eigenvalues : (3,) ascending.
    normal4 : (3, 3, 3, 3) normal moment of the faces.
    tol : relative eigenvalue gap below which two axes count as degenerate.

    Returns
    -------
    (3, 3) float64 right-handed frame (rows keep their PCA order where PCA decides it).
    """
    lam = np.maximum(np.asarray(eigenvalues, dtype=np.float64), 0.0)
    top = max(lam[2], 1e-300)
    low_pair = (lam[1] - lam[0]) <= tol * max(lam[1], 1e-300)
    high_pair = (lam[2] - lam[1]) <= tol * top
    out = np.array(frame, dtype=np.float64)
    if low_pair and high_pair:
        for _ in range(3):
            for axis in range(3):
                out = align_about(out, axis, normal4)
    elif high_pair:
        out = align_about(out, 0, normal4)
    elif low_pair:
        out = align_about(out, 2, normal4)
    return orient_frame(out)


def frame_from_moments(moments, align_degenerate=True, tol=DEFAULT_DEGENERATE_TOL):
    """Part frame from :class:`SurfaceMoments` (area mode, see module docstring)."""
    frame, vals = frame_from_covariance(moments.covariance())
    if align_degenerate:
        frame = align_degenerate_axes(frame, vals, moments.normal4, tol)
    return frame


def part_frames(vertices, faces, face_part, mode="area", align_degenerate=True,
                tol=DEFAULT_DEGENERATE_TOL, moments=None):
    """PCA frame of every part.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64.
    face_part : (m,) int, parts 0 .. P-1, each non-empty.
    mode : ``"area"`` (default) or ``"vertices"`` (Eq. 1 literally), see module docstring.
    moments : optional list of P :class:`SurfaceMoments` of the parts (:func:`group_moments`),
        computed when omitted.

    Returns
    -------
    (P, 3, 3) float64 frames (rows x, y, z).
    """
    if mode not in FRAME_MODES:
        raise ParameterError(f"frame mode must be one of {FRAME_MODES}, got {mode!r}")
    face_part = np.asarray(face_part, dtype=np.int64)
    n_parts = int(face_part.max()) + 1
    if moments is None:
        moments = group_moments(vertices, faces, face_part, n_parts)
    frames = np.empty((n_parts, 3, 3))
    verts = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    for p in range(n_parts):
        if mode == "area":
            frame, vals = frame_from_covariance(moments[p].covariance())
        else:
            pts = verts[np.unique(faces[face_part == p])]
            frame, vals = frame_from_covariance(np.cov(pts.T, bias=False))
        if align_degenerate:
            frame = align_degenerate_axes(frame, vals, moments[p].normal4, tol)
        frames[p] = frame
    return frames


def blend_target(interface, k, part_frames_, face_part, weight, face_area, part_areas):
    """(3, 3) frame both parts of ``interface`` (index ``k``) are blended towards.

    The frame of the part whose blend band covers the larger share of it, ``sum A w_k`` over its
    faces over its area (the first part on ties): that part keeps its own frame up to the
    interface and the other turns towards it within its band. The paper blends both towards the
    interface's PCA frame, but the in-plane axes of a cut follow the outline of the cut, 20 to 55
    degrees from the parts' frames on the topology-optimisation dev meshes, so a small part whose
    band covers most of it (``idler_riser``, ``octagonal_pocket``) was labelled in a frame that
    fits neither part.

    Parameters
    ----------
    interface : Interface; k : int, its column in ``weight``.
    part_frames_ : (P, 3, 3) float64; face_part : (m,) int64.
    weight : (m, K) float64 blend weights (:func:`blend_weight`); face_area : (m,) float64.
    part_areas : (P,) float64.
    """
    share = [float(np.sum((face_area * weight[:, k])[face_part == p])) / part_areas[p]
             for p in interface.parts]
    return np.array(part_frames_[interface.parts[int(np.argmax(share))]])


def _cube_group():
    """(24, 3, 3) signed permutation matrices with determinant +1."""
    mats = []
    for perm in permutations(range(3)):
        for signs in np.ndindex(2, 2, 2):
            g = np.zeros((3, 3))
            g[np.arange(3), perm] = np.where(np.array(signs) == 0, 1.0, -1.0)
            if np.linalg.det(g) > 0:
                mats.append(g)
    return np.array(mats)


CUBE_GROUP = _cube_group()


def match_frame(frame, reference):
    """The frame equivalent to ``frame`` under axis permutation/sign (same six label
    directions) that is closest to ``reference``; (3, 3) right-handed."""
    candidates = CUBE_GROUP @ frame
    score = np.einsum("gij,ij->g", candidates, reference)
    return candidates[int(np.argmax(score))]


def rotation_to_quaternion(mats):
    """(k, 4) unit quaternions (w, x, y, z) of (k, 3, 3) rotation matrices."""
    r = np.asarray(mats, dtype=np.float64)
    m00, m11, m22 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    k = np.stack([
        np.stack([m00 + m11 + m22, r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0],
                  r[:, 1, 0] - r[:, 0, 1]], -1),
        np.stack([r[:, 2, 1] - r[:, 1, 2], m00 - m11 - m22, r[:, 0, 1] + r[:, 1, 0],
                  r[:, 0, 2] + r[:, 2, 0]], -1),
        np.stack([r[:, 0, 2] - r[:, 2, 0], r[:, 0, 1] + r[:, 1, 0], m11 - m00 - m22,
                  r[:, 1, 2] + r[:, 2, 1]], -1),
        np.stack([r[:, 1, 0] - r[:, 0, 1], r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1],
                  m22 - m00 - m11], -1),
    ], axis=1) / 3.0
    _, vecs = np.linalg.eigh(k)
    return vecs[:, :, -1]


def quaternion_to_rotation(q):
    """(k, 3, 3) rotation matrices of (k, 4) quaternions (w, x, y, z), normalised first."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def blend_weight(distance, blend_distance):
    """Interface weight in [0, 1]: 1 at the interface, 0 from ``blend_distance`` on,
    C1-smooth in between (``1 - smoothstep(d / D)``)."""
    t = np.clip(np.asarray(distance, dtype=np.float64) / blend_distance, 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def mean_edge_length(vertices, faces):
    """Mean length of the undirected edges of a triangle mesh."""
    edges, _ = unique_edges(faces)
    v = np.asarray(vertices, dtype=np.float64)
    return float(np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).mean())


def interface_distances(vertices, faces, face_part, interfaces, limit):
    """Geodesic distance of every face to each interface, measured inside the face's part.

    Dijkstra over the mesh edges (edge lengths) restricted to edges of the part, from
    the interface's vertices; a face takes the mean of its three vertices' distances.

    Returns
    -------
    (m, len(interfaces)) float64, ``inf`` beyond ``limit`` or for faces of other parts.
    """
    faces = np.asarray(faces, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    edges, faces_of_edge = edge_faces(faces)
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    part_of = face_part[faces_of_edge]
    out = np.full((len(faces), len(interfaces)), np.inf)
    for k, itf in enumerate(interfaces):
        for p in itf.parts:
            keep = (part_of == p).any(axis=1)
            e = edges[keep]
            graph = sp.csr_matrix((np.concatenate([length[keep]] * 2),
                                   (np.concatenate([e[:, 0], e[:, 1]]),
                                    np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n))
            dist = dijkstra(graph, directed=True, indices=itf.vertices, min_only=True,
                            limit=limit)
            mine = face_part == p
            out[mine, k] = dist[faces[mine]].mean(axis=1)
    return out


@dataclass
class FrameField:
    """Frames of a part segmentation.

    face_frame : (m, 3, 3) float64 blended frame of each face (rows x, y, z).
    part_frames : (P, 3, 3) float64 frame of each part (the chosen candidate, see
        :mod:`core.segmentation.frame_choice`; PCA with ``choose="pca"``).
    interfaces : list of Interface records with ``frame`` (3, 3) set.
    face_interface : (m,) int64 interface next to each face (a vertex on it), -1 where none.
    face_interface_axis : (m, 3) float64 x-axis of that interface
        (:func:`core.segmentation.parts.interface_x_axis`,
        Eq. 3 term 4), NaN rows where none.
    face_interface_distance : (m,) float64 geodesic distance to the nearest interface of
        the face's part (inf beyond the blend distance or without interface).
    blend_distance : float, in mesh units.
    part_frame_source : tuple of P str, where each part's frame comes from (``"pca"``,
        ``"world"`` or ``"aligned"``).
    part_frame_energy : (P, 3) float64 labeling energy of the candidates ``pca``, ``world``,
        ``aligned`` (:func:`core.segmentation.frame_choice.labeling_energy`), NaN when not scored.
    """

    face_frame: np.ndarray
    part_frames: np.ndarray
    interfaces: list
    face_interface: np.ndarray
    face_interface_axis: np.ndarray
    face_interface_distance: np.ndarray
    blend_distance: float
    part_frame_source: tuple = ()
    part_frame_energy: np.ndarray = None


def compute_frames(mesh, face_part, blend_distance=None, mode="area", align_degenerate=True,
                   degenerate_tol=DEFAULT_DEGENERATE_TOL, interfaces=None, choose="energy",
                   lam=0.5):
    """Part, interface and blended per-face frames (paper Sect. 2.2).

    Each part's frame is the candidate (PCA, world axes, best normal-aligning rotation) of least
    labeling energy (:mod:`core.segmentation.frame_choice`), or plain PCA with ``choose="pca"``.
    Each face of part p gets p's frame rotated towards the frame of every interface
    of p within ``blend_distance`` (geodesic, inside p). The interface frame is the frame of
    the part whose band covers the larger share of it (:func:`blend_target`), first
    re-expressed by the axis permutation/sign closest to p's frame (same six label
    directions), so the blend does not spin; rotations are averaged as quaternions
    (weighted chordal mean, weights from :func:`blend_weight`; the part keeps weight
    ``1 - sum`` of the interface weights, interface weights are normalised if they
    exceed 1). At an interface the face frame equals the interface frame (up to
    permutation/sign of axes), from ``blend_distance`` on it equals the part frame.

    Parameters
    ----------
    mesh : object with ``vertices`` (n, 3) and ``faces`` (m, 3).
    face_part : (m,) int parts 0 .. P-1.
    blend_distance : float > 0 in mesh units, default 4 x mean edge length.
    mode, align_degenerate, degenerate_tol : see :func:`part_frames`.
    interfaces : optional precomputed list from :func:`core.segmentation.parts.interfaces`.
    choose : ``"energy"`` (default) or ``"pca"``.
    lam : float, lambda of Eq. 3 in the candidates' labeling energy.

    Returns
    -------
    FrameField
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    face_part = validate_face_part(mesh, face_part)
    if blend_distance is None:
        blend_distance = 4.0 * mean_edge_length(vertices, faces)
    blend_distance = float(blend_distance)
    if not np.isfinite(blend_distance) or blend_distance <= 0:
        raise ParameterError(f"blend_distance must be a positive length, got {blend_distance}")
    if not 0.0 <= degenerate_tol < 1.0:
        raise ParameterError(f"degenerate_tol must be in [0, 1), got {degenerate_tol}")
    if choose not in FRAME_CHOICES:
        raise ParameterError(f"choose must be one of {FRAME_CHOICES}, got {choose!r}")
    moments = group_moments(vertices, faces, face_part, int(face_part.max()) + 1)
    frames = part_frames(vertices, faces, face_part, mode, align_degenerate, degenerate_tol,
                         moments)
    source, energy = ("pca",) * len(frames), np.full((len(frames), 3), np.nan)
    if choose == "energy":
        from core.segmentation.frame_choice import choose_part_frames

        chosen = choose_part_frames(vertices, faces, face_part, frames, lam, moments)
        frames, source, energy = chosen.frames, chosen.source, chosen.energy
    n_parts = len(frames)
    face_area = face_geometry(vertices, faces)[0]
    areas = np.bincount(face_part, weights=face_area, minlength=n_parts)
    itfs = find_interfaces(mesh, face_part) if interfaces is None else interfaces
    dist = interface_distances(vertices, faces, face_part, itfs, blend_distance)
    weight = blend_weight(dist, blend_distance)
    itfs = [replace(itf, frame=blend_target(itf, k, frames, face_part, weight, face_area, areas))
            for k, itf in enumerate(itfs)]

    face_frame = frames[face_part].copy()
    total = weight.sum(axis=1) if itfs else np.zeros(len(faces))
    touched = np.flatnonzero(total > 0)
    if len(touched):
        scale = np.maximum(total[touched], 1.0)
        w_int = weight[touched] / scale[:, None]
        w_part = 1.0 - w_int.sum(axis=1)
        parts_t = face_part[touched]
        q_part = rotation_to_quaternion(frames)[parts_t]
        acc = w_part[:, None, None] * q_part[:, :, None] * q_part[:, None, :]
        for k, itf in enumerate(itfs):
            for p in itf.parts:
                sel = (parts_t == p) & (w_int[:, k] > 0)
                if not sel.any():
                    continue
                q = rotation_to_quaternion(match_frame(itf.frame, frames[p])[None])[0]
                acc[sel] += w_int[sel, k][:, None, None] * np.outer(q, q)[None]
        _, vecs = np.linalg.eigh(acc)
        face_frame[touched] = quaternion_to_rotation(vecs[:, :, -1])
    face_interface, axis = face_interface_axes(faces, face_part, itfs, vertices)
    nearest = dist.min(axis=1) if itfs else np.full(len(faces), np.inf)
    return FrameField(face_frame, frames, itfs, face_interface, axis, nearest, blend_distance,
                      source, energy)

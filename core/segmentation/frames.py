# SPDX-License-Identifier: LGPL-2.1-or-later
"""Frames of parts and interfaces, blended per face (paper Sect. 2.2).

A frame is a (3, 3) float64 array whose rows are the local x, y, z axes in world
coordinates: orthonormal and right-handed (``det == +1``). Each part's own frame (PCA,
Eq. 1, with degenerate axes aligned to the normals) is :mod:`core.segmentation.part_frame`;
the choice among candidate frames is :mod:`core.segmentation.frame_choice`; this module
blends the chosen part frames towards each interface (:func:`compute_frames`).
"""
from dataclasses import dataclass, replace
from itertools import permutations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from core.errors import ParameterError
from core.mesh_topology import edge_faces, unique_edges
from core.segmentation.frame_choice import choose_part_frames
from core.segmentation.part_frame import (DEFAULT_DEGENERATE_TOL, face_geometry, group_moments,
                                          part_frames)
from core.segmentation.parts import (face_interface_axes, interfaces as find_interfaces,
                                     validate_face_part)

FRAME_CHOICES = ("energy", "pca")


def blend_target(interface, k, part_frames_, face_part, weight, face_area, part_areas):
    """(3, 3) frame both parts of ``interface`` (index ``k``) are blended towards.

    The frame of the part whose blend band covers the larger share of it, ``sum A w_k`` over its
    faces over its area (the first part on ties): that part keeps its own frame up to the
    interface and the other turns towards it within its band. The paper blends both towards the
    interface's PCA frame, but the in-plane axes of a cut follow the outline of the cut, often
    tens of degrees away from the parts' frames on topology-optimisation results, so a small part
    whose band covers most of it would be labelled in a frame that fits neither part.

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
    mode, align_degenerate, degenerate_tol : see :func:`core.segmentation.part_frame.part_frames`.
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

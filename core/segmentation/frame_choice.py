# SPDX-License-Identifier: LGPL-2.1-or-later
"""Choice of each part's frame among candidates, by the labeling energy they give.

PCA (Eq. 1) is the paper's frame, but topology-optimisation results are built on a voxel grid
aligned with the design domain, and the PCA of an L-shaped or bracket-shaped part turns away from
that grid. Each part therefore gets the best of three candidates:

- ``"pca"``: :func:`core.segmentation.part_frame.part_frames` (PCA with degenerate axes aligned
  to the normals, the frame the stage used before);
- ``"world"``: the world axes (identity);
- ``"aligned"``: the rotation that minimises the area-weighted cubic misalignment of the normals,
  ``sum A (1 - sum_k (n.a_k)^4) / 2`` (:func:`core.segmentation.part_frame.cubic_energy`), found by
  cyclic closed-form rotations about each axis from the PCA and from the world start (the better
  of the two results).

Score of a candidate frame ``R`` on part ``p``: Eq. 3's energy without the penalty terms for the
nearest-direction labels ``l_i`` in ``R`` (the start of the HBECVT sweeps),

    E_p(R) = sum_{i in p} ||n_i - c_{l_i}||^2 + lambda * #{edges of p whose two faces' l differ},

so a frame that labels the part by fewer, cleaner charts wins. Ties keep the earlier candidate
(order ``pca``, ``world``, ``aligned``).
"""
from dataclasses import dataclass

import numpy as np

from core.mesh_topology import edge_faces
from core.segmentation.part_frame import (align_about, cubic_energy, face_geometry,
                                          group_moments, orient_frame)
from core.segmentation.labeling import LAMBDA

CANDIDATES = ("pca", "world", "aligned")


@dataclass(frozen=True)
class FrameChoice:
    """Chosen frame of every part and the scores behind the choice.

    frames : (P, 3, 3) float64 chosen frame of each part (rows x, y, z, right-handed).
    source : tuple of P str, candidate name of each chosen frame (one of :data:`CANDIDATES`).
    candidates : (P, 3, 3, 3) float64 candidate frames, in :data:`CANDIDATES` order.
    energy : (P, 3) float64 labeling energy ``E_p`` of each candidate (dimensionless).
    """

    frames: np.ndarray
    source: tuple
    candidates: np.ndarray
    energy: np.ndarray


def best_aligned_frame(normal4, start, sweeps=20, tol=1e-12):
    """Rotation minimising the cubic misalignment of the normals, from ``start``.

    Parameters
    ----------
    normal4 : (3, 3, 3, 3) float64 normal moment
        (:class:`core.segmentation.part_frame.SurfaceMoments`).
    start : (3, 3) float64 start frame (rows x, y, z).
    sweeps : int, cap on cycles of rotations about x, y and z.
    tol : float, stop when a cycle lowers the energy by less than ``tol`` times the area.

    Returns
    -------
    (3, 3) float64 right-handed frame (a local minimum of the cubic energy).
    """
    frame = np.array(start, dtype=np.float64)
    area = float(np.trace(normal4.reshape(9, 9)[np.ix_([0, 4, 8], [0, 4, 8])]))
    energy = cubic_energy(normal4, frame)
    for _ in range(int(sweeps)):
        for axis in range(3):
            frame = align_about(frame, axis, normal4)
        new = cubic_energy(normal4, frame)
        done = energy - new <= tol * max(area, 1e-300)
        energy = new
        if done:
            break
    return orient_frame(frame)


def candidate_frames(pca, normal4):
    """(3, 3, 3) float64 candidate frames of one part, in :data:`CANDIDATES` order.

    ``pca`` : (3, 3) PCA frame of the part (:func:`core.segmentation.part_frame.part_frames`);
    ``normal4`` : (3, 3, 3, 3) normal moment of the part's faces.
    """
    world = np.eye(3)
    starts = [best_aligned_frame(normal4, s) for s in (pca, world)]
    energies = [cubic_energy(normal4, f) for f in starts]
    return np.stack([pca, world, starts[int(np.argmin(energies))]])


def labeling_energy(normals, neighbour_pairs, face_part, frames, lam=LAMBDA):
    """(P,) float64 energy ``E_p`` (module docstring) of nearest-direction labels per part.

    Parameters
    ----------
    normals : (m, 3) float64 unit face normals.
    neighbour_pairs : (k, 2) int64 pairs of edge-adjacent faces of the same part.
    face_part : (m,) int64 part of each face.
    frames : (P, 3, 3) float64 frame of each part (rows x, y, z).
    lam : float, lambda of Eq. 3.

    Notes
    -----
    The nearest of the six directions ``+-a_k`` is the axis of largest ``|n . a_k|`` with the sign
    of ``n . a_k`` (as :func:`core.segmentation.labeling.nearest_direction_labels`), and its term-1
    cost is ``2 - 2 |n . a_k|``; one frame per part keeps this a (m, 3) product.
    """
    n_parts = len(frames)
    local = np.einsum("fij,fj->fi", frames[face_part], normals)
    axis = np.argmax(np.abs(local), axis=1)
    best = local[np.arange(len(local)), axis]
    labels = 2 * axis + (best < 0)
    unary = np.bincount(face_part, weights=2.0 - 2.0 * np.abs(best), minlength=n_parts)
    a, b = neighbour_pairs[:, 0], neighbour_pairs[:, 1]
    cut = np.bincount(face_part[a], weights=(labels[a] != labels[b]).astype(np.float64),
                      minlength=n_parts)
    return unary + lam * cut


def choose_part_frames(vertices, faces, face_part, pca_frames, lam=LAMBDA, moments=None):
    """Frame of every part: the candidate of least labeling energy (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64.
    face_part : (m,) int64 parts 0 .. P-1, each non-empty.
    pca_frames : (P, 3, 3) float64 PCA frame of each part
        (:func:`core.segmentation.part_frame.part_frames`).
    lam : float, lambda of Eq. 3.
    moments : optional list of P :class:`core.segmentation.part_frame.SurfaceMoments` of the parts,
        computed when omitted.

    Returns
    -------
    FrameChoice
    """
    faces = np.asarray(faces, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    n_parts = len(pca_frames)
    if moments is None:
        moments = group_moments(vertices, faces, face_part, n_parts)
    cands = np.stack([candidate_frames(pca_frames[p], moments[p].normal4)
                      for p in range(n_parts)])
    normals = face_geometry(vertices, faces)[1]
    ef = edge_faces(faces)[1]
    ef = ef[(ef >= 0).all(axis=1)]
    pairs = ef[face_part[ef[:, 0]] == face_part[ef[:, 1]]]
    energy = np.stack([labeling_energy(normals, pairs, face_part, cands[:, k], lam)
                       for k in range(len(CANDIDATES))], axis=1)
    pick = np.argmin(energy, axis=1)
    frames = cands[np.arange(n_parts), pick]
    return FrameChoice(frames, tuple(CANDIDATES[k] for k in pick), cands, energy)

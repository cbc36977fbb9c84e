# SPDX-License-Identifier: LGPL-2.1-or-later
"""Two-sided least-squares fit of a subdivision cage to a target (``--fit-mode best-fit``).

The fine limit points ``X = M V`` (``M`` the limit map of the fit, ``V`` the base
vertices) should lie on the target and the target on the limit surface. Each
Gauss-Newton round linearises both distances point-to-plane:

* forward, for every fine limit point ``X_j`` with closest target point ``c_j`` and
  pseudo-normal ``n_j``: ``r_j = n_j . (X_j - c_j)``;
* backward, for area-weighted samples ``s_k`` of the target (normal ``m_k``) with
  closest point ``y_k = B_k X`` on the triangulated limit surface (``B`` the barycentric
  rows): ``r_k = m_k . (B_k M V - s_k)``;

(a pair counts only if the two surfaces' normals there are within 60 degrees, so the
far wall of a thin member does not pull the near one through), and minimises

    E(V) = mean_j r_j^2 + mean_k r_k^2 + lam * |D (V - V_init)|^2 / n_base
           + mu * |V - V_prev|^2 / n_base

with ``D`` the umbrella Laplacian of the cage (a small smoothness term that keeps the
cage as fair as it started; ``lam`` is scaled by the data term's diagonal so it is unit
free) and a Levenberg-Marquardt damping ``mu`` towards the previous round. Closest
points change between rounds; the rounds stop when the two-sided RMS distance improves
by less than ``tol`` (relative) or after ``rounds``.
"""
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from core.fitting.responses import vertex_normals
from core.quality import sample_surface
from core.subdivision.catmull_clark import mesh_topology
from core.target_surface import TargetSurface

_DENSE_UNKNOWNS = 3000
COMPATIBLE = 0.5
"""Pairs count only if their two unit normals have a dot product above this (60 degrees)."""


@dataclass
class BestFitResult:
    """Outcome of :func:`best_fit`.

    vertices : (n, 3) float64 fitted base vertices (model units), the round with the
        lowest RMS distance.
    rounds : int, Gauss-Newton rounds run.
    rms : list of float, two-sided RMS distance (forward and backward mean squares
        averaged) before each round and after the last (model units).
    stopped : ``'converged'`` or ``'rounds'``.
    """

    vertices: np.ndarray
    rounds: int
    rms: list
    stopped: str


def best_fit(base, mapping, triangles, target, rounds=10, smoothness=1e-2, damping=1e-3,
             tol=5e-3, samples=None, seed=0, start=None):
    """Fit the cage's limit surface to the target in the two-sided least-squares sense.

    Parameters
    ----------
    base : PolyMesh, the cage (its vertices are the start).
    mapping : (n_fine, n_base) sparse, fine limit points ``X = mapping @ V``.
    triangles : (t, 3) int64 triangles of the fine mesh.
    target : TargetSurface
    rounds : int >= 0, most Gauss-Newton rounds.
    smoothness : float >= 0, ``lam`` (relative to the data term).
    damping : float > 0, ``mu`` (relative to the data term).
    tol : float, relative RMS improvement below which the rounds stop.
    samples : int or None, target samples for the backward term (default: as many as
        fine points, at least 2000).
    seed : int, sampling seed (deterministic).
    start : (n, 3) float or None, first iterate (default: the cage's vertices, which stay
        the smoothness term's reference either way).

    Returns
    -------
    BestFitResult
    """
    mapping = sp.csr_matrix(mapping)
    n_fine, n_base = mapping.shape
    count = max(n_fine, 2000) if samples is None else int(samples)
    rng = np.random.default_rng(seed)
    points = sample_surface(target.vertices, target.faces, count, rng)
    sample_normal = target.closest(points).normal
    laplacian = _umbrella(base, n_base)
    smooth = sp.block_diag([laplacian.T @ laplacian] * 3, format="csr")
    identity = sp.identity(3 * n_base, format="csr")
    V_init = np.asarray(base.vertices, dtype=np.float64)
    v_init = V_init.T.reshape(-1)
    V = V_init.copy() if start is None else np.array(start, dtype=np.float64)
    rms = []
    best = (np.inf, V)
    stopped = "rounds"
    for done in range(rounds + 1):
        X = mapping @ V
        forward = target.closest(X)
        fitted = TargetSurface(X, triangles, "fitted surface")
        back = fitted.nearest(points)
        rms.append(float(np.sqrt(0.5 * (np.mean(forward.distance ** 2)
                                        + np.mean(back.distance ** 2)))))
        if rms[-1] < best[0]:
            best = (rms[-1], V)
        if len(rms) >= 2 and rms[-2] - rms[-1] <= tol * rms[-2]:
            stopped = "converged"
            break
        if done == rounds:
            break
        rows = sp.csr_matrix((back.bary.reshape(-1), triangles[back.face].reshape(-1),
                              np.arange(0, 3 * count + 1, 3)), shape=(count, n_fine))
        # pairs whose normals disagree (the far wall of a thin member) are left out
        keep_f = _dot(vertex_normals(X, triangles), forward.normal) > COMPATIBLE
        keep_b = _dot(fitted.face_normals[back.face], sample_normal) > COMPATIBLE
        J_f = _plane_rows(forward.normal * keep_f[:, None], mapping)
        J_b = _plane_rows(sample_normal * keep_b[:, None], rows @ mapping)
        b_f = _dot(forward.normal, forward.point) * keep_f
        b_b = _dot(sample_normal, points) * keep_b
        system = (J_f.T @ J_f) / n_fine + (J_b.T @ J_b) / count
        scale = float(system.diagonal().mean())
        system = system + (smoothness * scale) * smooth + (damping * scale) * identity
        rhs = ((J_f.T @ b_f) / n_fine + (J_b.T @ b_b) / count
               + (smoothness * scale) * (smooth @ v_init) + (damping * scale) * V.T.reshape(-1))
        V = _solve_spd(system, rhs).reshape(3, -1).T
    return BestFitResult(best[1], len(rms) - 1, rms, stopped)


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _solve_spd(system, rhs):
    """Solve a symmetric positive definite sparse system: dense Cholesky up to
    ``_DENSE_UNKNOWNS`` unknowns (the Catmull-Clark limit stencils make it about 15 %
    full), sparse LU with a symmetric minimum-degree ordering above."""
    if system.shape[0] <= _DENSE_UNKNOWNS:
        return scipy.linalg.solve(system.toarray(), rhs, assume_a="pos")
    return spsolve(system.tocsc(), rhs, permc_spec="MMD_AT_PLUS_A")


def _plane_rows(normal, A):
    """(k, 3 n) sparse rows ``v -> normal_j . (A V)_j`` for ``v = [Vx, Vy, Vz]``."""
    return sp.hstack([sp.diags(normal[:, axis]) @ A for axis in range(3)], format="csr")


def _umbrella(base, n):
    """(n, n) sparse umbrella Laplacian ``I - D^-1 A`` over the cage's edges."""
    edges = mesh_topology(base.face_vertices, base.face_offsets, n).edges
    i, j = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
    adjacency = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return sp.identity(n, format="csr") - sp.diags(1.0 / np.maximum(degree, 1)) @ adjacency

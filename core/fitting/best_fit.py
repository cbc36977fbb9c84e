# SPDX-License-Identifier: LGPL-2.1-or-later
"""Two-sided least-squares fit of a subdivision cage to a target (``--fit-mode best-fit``).

The fine limit points ``X = M V`` (``M`` the limit map of the fit, ``V`` the base
vertices) should lie on the target and the target on the limit surface. Each
Gauss-Newton round linearises both distances point-to-plane:

* forward, for every fine limit point ``X_j`` with closest target point ``c_j`` and
  pseudo-normal ``n_j``: ``r_j = n_j . (X_j - c_j)`` (the mean of the rows of its two closest
  points where it lies on the target's medial axis,
  :meth:`core.target_surface.ClosestPoints.mean_plane`);
* backward, for area-weighted samples ``s_k`` of the target (normal ``m_k``) with
  closest point ``y_k = B_k X`` on the triangulated limit surface (``B`` the barycentric
  rows): ``r_k = m_k . (B_k M V - s_k)``;

(a pair counts fully where the two surfaces' normals there are within about 50 degrees and
not at all beyond about 70, so the far wall of a thin member does not pull the near one
through; the weight ramps between, and the limit surface's normal is interpolated from its
vertex normals, so that a pair whose closest point lies on an edge of the limit mesh gets
the same weight whichever triangle holds it, and rounding cannot switch a pair on or off),
and minimises

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
import scipy.sparse as sp

from core.compiled import each_on_a_core
from core.fitting.responses import InsideBounds, vertex_normals
from core.fitting.spd_solve import solve_spd
from core.geometry import scatter_add
from core.subdivision.catmull_clark import mesh_topology
from core.tolerances import CONTACT
from core.types import PolyMesh


@dataclass(frozen=True)
class BestFitSettings:
    """Tuned constants of the least-squares fit (:func:`best_fit`)."""

    compatible: float = 0.5
    """Dot product of a closest-point pair's two unit normals at which the pair counts half
    (:func:`compatibility`)."""
    compatible_ramp: float = 0.15
    """Half width of the dot products over which a pair's weight ramps from 0 to 1."""


BEST_FIT = BestFitSettings()
"""The settings this module runs with."""


@dataclass
class BestFitResult:
    """Outcome of :func:`best_fit`.

    vertices : (n, 3) float64 fitted base vertices (model units), the round with the
        lowest RMS distance (of the solved rounds, for a refit).
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
             tol=5e-3, samples=None, seed=0, start=None, stiffness=None, refit=False):
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
    stiffness : (n,) float64 >= 1 or None, per base vertex factor on the smoothness term
        (the rows of ``D`` at that vertex); None is all ones.
    refit : bool, ``start`` is a fit with other smoothness weights: it is not a candidate
        for the result (its RMS distance is lower than any fit with stiffer weights can
        reach), the first solved round is.

    Returns
    -------
    BestFitResult
    """
    system = NormalEquations(base, mapping, smoothness, damping, stiffness)
    n_fine = system.n_fine
    count = max(n_fine, 2000) if samples is None else int(samples)
    points, sample_normal = target.samples(count, seed)
    V = system.V_init.copy() if start is None else np.array(start, dtype=np.float64)
    own, ones = np.arange(n_fine)[:, None], np.ones((n_fine, 1))
    rms = []
    best = (np.inf, V)
    stopped = "rounds"
    for done in range(rounds + 1):
        X = mapping @ V
        forward = target.closest(X)
        back, _ = target.samples_nearest(X, triangles, count, seed)
        rms.append(float(np.sqrt(0.5 * (np.mean(forward.distance ** 2)
                                        + np.mean(back.distance ** 2)))))
        if rms[-1] < best[0] and not (refit and done == 0 and rounds > 0):
            best = (rms[-1], V)
        if len(rms) >= 2 + refit and rms[-2] - rms[-1] <= tol * rms[-2]:
            stopped = "converged"
            break
        if done == rounds:
            break
        # pairs whose normals disagree (the far wall of a thin member) are left out
        normals = vertex_normals(X, triangles)
        plane_normal, plane_offset = forward.mean_plane()
        keep_f = compatibility(_dot(normals, plane_normal))
        keep_b = compatibility(_dot(_interpolated(normals, triangles[back.face], back.bary),
                                    sample_normal))
        V = system.solve(V, [(plane_normal * keep_f[:, None], own, ones,
                              plane_offset * keep_f, n_fine),
                             (sample_normal * keep_b[:, None], triangles[back.face], back.bary,
                              _dot(sample_normal, points) * keep_b, count)])
    return BestFitResult(best[1], len(rms) - 1, rms, stopped)


def pull_inside(base, mapping, target, start, margin, rounds=2, smoothness=1e-2,
                damping=1e-3, stiffness=None, start_closest=None):
    """Move the fine limit points that lie outside the target (or within ``margin`` of
    it) to ``margin`` inside it, changing the cage as little as the regularisation allows.

    One-sided point-to-plane Gauss-Newton: each round, every fine limit point ``X_j``
    with signed distance ``d_j > -margin`` (closest point ``c_j``, pseudo-normal ``n_j``)
    gets the residual ``n_j . (X_j - c_j) + margin``; the points deeper inside are free.
    The same smoothness and damping terms as :func:`best_fit` hold the rest of the cage,
    with ``start`` as the smoothness term's reference (not the cage: its limit surface
    cuts convex corners, and pulling towards its shape would cut them again, which more than
    doubles the inside fit's largest distance on a polycube-like part).
    Used as the inside fit's start: the least-squares fit lies about half outside the
    target, and the relaxed gradient projection starts better from just inside it.

    Parameters
    ----------
    base : PolyMesh, the cage (its faces).
    mapping : (n_fine, n_base) sparse, ``X = mapping @ V``.
    target : TargetSurface
    start : (n_base, 3) float64 base vertices to start from (model units).
    margin : float >= 0, depth below the target surface to pull to (model units).
    rounds : int >= 0
    smoothness, damping, stiffness : as in :func:`best_fit`.
    start_closest : core.target_surface.ClosestPoints or None, the closest points of the
        start's fine points ``mapping @ start`` if known (the stiffer pulls of
        :func:`core.fitting.fit._pulled_inside` all start there). After the first round
        only the points not proven deeper than ``margin`` are queried
        (:class:`core.fitting.responses.InsideBounds`; the same rows either way).

    Returns
    -------
    (n_base, 3) float64 base vertices.
    """
    V = np.array(start, dtype=np.float64)
    system = NormalEquations(PolyMesh(V, base.face_vertices, base.face_offsets), mapping,
                             smoothness, damping, stiffness)
    known = InsideBounds(CONTACT * target.diagonal, margin)
    for done in range(rounds):
        X = mapping @ V
        query = known.undecided(X)
        if done == 0 and start_closest is not None:
            near = start_closest
            known.record(X, query, near)
        else:
            near = known.closest(target, X, query)
        active = near.signed > -margin
        if not active.any():
            break
        plane_normal, plane_offset = near.mean_plane()
        normal, b = np.zeros_like(X), np.zeros(len(X))
        normal[query] = plane_normal * active[:, None]
        b[query] = (plane_offset - margin) * active
        V = system.solve(V, [(normal, np.arange(len(X))[:, None], np.ones((len(X), 1)), b,
                              system.n_fine)])
    return V


class NormalEquations:
    """Regularised point-to-plane normal equations on the cage's vertices.

    For data terms ``(normal, corners, weights, b, count)`` -- rows
    ``normal_j . sum_c weights_jc X_(corners_jc) = b_j`` on the fine points
    ``X = mapping @ V``, weighted by ``1 / count`` -- :meth:`solve` minimises their sum
    plus ``lam s |D (V - V_init)|^2 + mu s |V - V_prev|^2`` (``s`` the mean diagonal of
    the data part, so ``lam`` and ``mu`` are unit free; ``D`` the cage's umbrella
    Laplacian). The smoothness matrix is built once per cage.

    Assembly: the data part's 3x3 blocks (coordinates ``a, b``) are
    ``M^T Z_ab M`` with ``Z_ab = sum_j (n_ja n_jb / count) w_j w_j^T`` on the fine
    points (``w_j`` the row's corner weights), six symmetric blocks built on the fine
    level two at a time (:class:`_FineEntries`, whose rows and columns they share) and
    mapped by two sparse products per pair of blocks (:meth:`_data_blocks`); a row through
    ``k`` corners costs ``k^2`` fine entries instead of the square of its base-vertex
    support.

    Solution: the matrix is symmetric positive definite and a few percent full (a base
    vertex is coupled to the vertices whose limit stencils share a fine point with its own);
    its upper triangle goes to a sparse ``L D L^T`` factorisation
    (:func:`core.fitting.spd_solve.solve_spd`).

    Parameters
    ----------
    base : PolyMesh, the cage (``V_init`` = its vertices).
    mapping : (n_fine, n_base) sparse
    smoothness, damping : float, ``lam`` and ``mu``.
    stiffness : (n_base,) float64 or None, per-vertex weights ``w`` of the smoothness
        rows: the term is ``lam s |W^(1/2) D (V - V_init)|^2`` (None: all ones).
    """

    def __init__(self, base, mapping, smoothness, damping, stiffness=None):
        self.mapping = sp.csr_matrix(mapping)
        self.n_fine, self.n_base = mapping.shape
        self.V_init = np.asarray(base.vertices, dtype=np.float64)
        laplacian = _umbrella(base, self.n_base)
        if stiffness is not None:
            laplacian = sp.diags(np.sqrt(np.asarray(stiffness, dtype=np.float64))) @ laplacian
        self.smooth = (laplacian.T @ laplacian).tocsr()
        self.smooth_init = (self.smooth @ self.V_init).T.reshape(-1)
        self.smoothness, self.damping = float(smoothness), float(damping)
        self._mapping_t = self.mapping.T.tocsr()
        # complex copies for the paired products of _data_blocks (their imaginary parts are 0)
        self._mapping_c, self._mapping_t_c = (_complex(self.mapping), _complex(self._mapping_t))

    def solve(self, V, terms):
        """(n_base, 3) float64 minimiser for the data ``terms`` and the previous ``V``."""
        n = self.n_base
        fine_rhs = sum(scatter_add(corners.reshape(-1),
                                   ((normal * (b / count)[:, None])[:, None, :]
                                    * weights[:, :, None]).reshape(-1, 3), self.n_fine)
                       for normal, corners, weights, b, count in terms)
        rhs = np.asarray(self._mapping_t @ fine_rhs).T.reshape(-1)
        piece = self._data_blocks(terms)
        scale = float(np.mean([piece[a, a].diagonal().mean() for a in range(3)]))
        rhs = (rhs + (self.smoothness * scale) * self.smooth_init
               + (self.damping * scale) * V.T.reshape(-1))
        regular = ((self.smoothness * scale) * self.smooth
                   + sp.identity(n, format="csr") * (self.damping * scale))
        # the upper triangle of blocks (``piece`` holds those with a <= c; the solver reads
        # no entry below the diagonal)
        blocks = [[None] * 3 for _ in range(3)]
        for (a, c), block in piece.items():
            blocks[a][c] = block + regular if a == c else block
        return solve_spd(sp.bmat(blocks, format="coo"), rhs).reshape(3, -1).T

    def _data_blocks(self, terms):
        """dict ``(a, b) -> (n_base, n_base)`` sparse: the data part's blocks ``M^T Z_ab M``.

        Two blocks go through the two sparse products together, as the real and imaginary
        parts of ``M^T (Z_ab + i Z_cd) M`` with a real ``M``: a real factor times a complex
        number rounds each part exactly as the real product does, so the parts are the two
        real products bit for bit, in about 0.6 of their time (the products' cost is their
        index work, which the two parts share).
        """
        fine = _FineEntries(terms)

        def product(pair):
            return self._mapping_t_c @ (fine.pair_matrix(*pair, self.n_fine) @ self._mapping_c)

        pairs = ((0, 1), (2, 3), (4, 5))
        blocks = {}
        # the three products are independent: on the cores (scipy's products release the
        # interpreter), each rounded as alone
        for (first, second), both in zip(pairs, each_on_a_core(product, pairs)):
            blocks[_PAIRS[first]], blocks[_PAIRS[second]] = both.real, both.imag
        return blocks


_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
"""The coordinate pairs ``(a, b)`` of the six distinct 3x3 blocks of the normal matrix."""


class _FineEntries:
    """The entries of the six fine-level blocks ``Z_ab`` of :meth:`NormalEquations.solve`
    (``_PAIRS`` order), which share their rows and columns.

    ``Z_ab = sum_j (n_ja n_jb / count) w_j w_j^T`` over the data rows ``j`` of every term
    ``(normal, corners, weights, b, count)``, entry ``(corners_jk, corners_jl)`` for each
    pair of a row's corners, duplicates summed.
    """

    def __init__(self, terms):
        rows, cols, self._weights, self._normals = [], [], [], []
        for normal, corners, weights, _, count in terms:
            pair = weights[:, :, None] * weights[:, None, :] / count
            rows.append(np.broadcast_to(corners[:, :, None], pair.shape).reshape(-1))
            cols.append(np.broadcast_to(corners[:, None, :], pair.shape).reshape(-1))
            self._weights.append(pair)
            self._normals.append(normal)
        self._rows, self._cols = np.concatenate(rows), np.concatenate(cols)

    def pair_matrix(self, first, second, n_fine):
        """(n_fine, n_fine) complex128 CSR ``Z_first + i Z_second`` (indices into ``_PAIRS``).

        Built with complex entries, its duplicates are summed part by part in the order the
        real blocks' are (the same rows and columns), and the entries that are zero in both
        parts are dropped, as adding the two real blocks drops them: the same matrix as
        ``Z_first + 1j * Z_second``, at half the sorting.
        """
        values = np.empty(len(self._rows), dtype=np.complex128)
        for part, block in ((values.real, first), (values.imag, second)):
            a, c = _PAIRS[block]
            part[:] = np.concatenate([((normal[:, a] * normal[:, c])[:, None, None] * pair)
                                      .reshape(-1) for normal, pair in zip(self._normals,
                                                                            self._weights)])
        matrix = sp.csr_matrix((values, (self._rows, self._cols)), shape=(n_fine, n_fine))
        matrix.eliminate_zeros()
        return matrix


def _complex(matrix):
    """A complex128 copy of a CSR matrix with its own index arrays and its entries in the same
    order (scipy's ``astype`` sorts them, in the arrays it may share with ``matrix``)."""
    return sp.csr_matrix((matrix.data.astype(np.complex128), matrix.indices.copy(),
                          matrix.indptr.copy()), shape=matrix.shape)


def compatibility(dots):
    """(k,) float64 in [0, 1]: the weight of pairs whose unit normals have the dot products
    ``dots`` ((k,) float64), 0 below ``compatible - compatible_ramp``, 1 above ``compatible
    + compatible_ramp`` (:class:`BestFitSettings`), linear between (a continuous weight, so
    that a dot product moved by rounding moves the fit by as little)."""
    low, ramp = BEST_FIT.compatible - BEST_FIT.compatible_ramp, BEST_FIT.compatible_ramp
    return np.clip((dots - low) / (2.0 * ramp), 0.0, 1.0)


def _interpolated(normals, corners, bary):
    """(k, 3) float64 unit normals at points with barycentric coordinates ``bary`` ((k, 3))
    in triangles with corners ``corners`` ((k, 3) int64) of a mesh with vertex normals
    ``normals`` ((n, 3)): continuous over the mesh, also across its edges and vertices."""
    mixed = np.einsum("kc,kcj->kj", bary, normals[corners])
    length = np.linalg.norm(mixed, axis=1, keepdims=True)
    return mixed / np.where(length > 0, length, 1.0)


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _umbrella(base, n):
    """(n, n) sparse umbrella Laplacian ``I - D^-1 A`` over the cage's edges."""
    edges = mesh_topology(base.face_vertices, base.face_offsets, n).edges
    i, j = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
    adjacency = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return sp.identity(n, format="csr") - sp.diags(1.0 / np.maximum(degree, 1)) @ adjacency

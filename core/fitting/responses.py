# SPDX-License-Identifier: LGPL-2.1-or-later
"""Responses of the fit stage (paper Eqs. 7-9) on a triangulated fine mesh, with gradients.

All functions take the fine-mesh vertex positions ``X`` ((n, 3) float64, model units)
and its triangles ``T`` ((t, 3) int64, counter-clockwise seen from outside) and
return gradients with respect to ``X`` as (n, 3) float64 arrays; mapping them to the
base mesh (Eq. 11) is the caller's job.

* :func:`volume` -- Eq. 7, the enclosed volume, with its exact gradient.
* :func:`packaging` -- Eq. 8, the summed outward penetration of the vertices through
  the target (one-sided, ``mode='inside'``) or the summed absolute distance to it
  (``mode='nearest'``), with its exact gradient for fixed target.
* :func:`thickness` / :func:`thickness_constraint` -- Eq. 9, the distance from every
  vertex along its inward normal to the opposite side of the surface itself, and a
  smooth aggregate constraint ``t_j >= t_min``.
"""
from dataclasses import dataclass, fields

import numpy as np

from core.compiled import numba

from core.geometry import face_cross, scatter_add
from core.target_surface import ClosestPoints, TargetSurface
from core.tolerances import CONTACT


def volume(X, T):
    """Enclosed volume (Eq. 7) and its exact gradient.

    Returns
    -------
    value : float, model units cubed (positive for an outward-oriented closed mesh).
    gradient : (n, 3) float64, ``d value / d X``; for vertex ``j`` it equals
        ``1/6 * sum over triangles (j, b, c) of X_b x X_c`` = one third of the
        area-weighted normal of its one-ring.
    """
    X = np.ascontiguousarray(X, dtype=np.float64)
    T = np.ascontiguousarray(T, dtype=np.int64)
    a, bc, gradient = _volume_terms(X, T)
    return float(np.einsum("ij,ij->", a, bc)) / 6.0, gradient


@numba.njit(cache=True, nogil=True)
def _volume_terms(X, T):
    """``(a, b x c, gradient)`` of :func:`volume`: the first corners and the cross products
    of the other two of the triangles, (t, 3) each, and the gradient (n, 3).

    The gradient sums, per vertex, ``b x c / 6`` of the triangles it is the first corner of
    in triangle order, then ``c x a / 6`` of those it is the second of, then ``a x b / 6``,
    each cross product's coordinates as ``numpy.cross`` computes them: the sums of one
    ``numpy.bincount`` per coordinate over the three stacked, bit for bit, without their
    arrays (the relaxed gradient projection evaluates the volume every iteration).
    """
    t = T.shape[0]
    a = np.empty((t, 3))
    bc = np.empty((t, 3))
    gradient = np.zeros((X.shape[0], 3))
    for f in range(t):
        p, q, r = X[T[f, 0]], X[T[f, 1]], X[T[f, 2]]
        a[f, 0], a[f, 1], a[f, 2] = p[0], p[1], p[2]
        bc[f, 0] = q[1] * r[2] - q[2] * r[1]
        bc[f, 1] = q[2] * r[0] - q[0] * r[2]
        bc[f, 2] = q[0] * r[1] - q[1] * r[0]
        for d in range(3):
            gradient[T[f, 0], d] += bc[f, d] / 6.0
    for corner in (1, 2):  # second corners over all triangles, then third corners
        for f in range(t):
            # the cross product of the corners after this one, in cyclic order
            u, w = X[T[f, (corner + 1) % 3]], X[T[f, (corner + 2) % 3]]
            v = T[f, corner]
            gradient[v, 0] += (u[1] * w[2] - u[2] * w[1]) / 6.0
            gradient[v, 1] += (u[2] * w[0] - u[0] * w[2]) / 6.0
            gradient[v, 2] += (u[0] * w[1] - u[1] * w[0]) / 6.0
    return a, bc, gradient


def packaging(X, target, mode="inside", known=None):
    """Packaging response (Eq. 8) against a :class:`TargetSurface`.

    Parameters
    ----------
    X : (n, 3) float64
    target : core.target_surface.TargetSurface
    mode : ``'inside'`` sums ``max(d_j, 0)`` (penetration out of the target, the
        paper's form) over the points more than ``CONTACT`` of the target's diagonal
        outside (a point that near is on the surface); ``'nearest'`` sums ``|d_j|``.
    known : InsideBounds or None, the queries of earlier calls on the same ``n`` points
        (``mode='inside'`` only): points proven still inside are not queried again.

    Returns
    -------
    value : float, model units.
    gradient : (n, 3) float64, the exact gradient of the signed distance,
        ``sign(d_j) (X_j - CPP_j) / |X_j - CPP_j|`` (the face normal where the closest point
        is inside a target face, Eq. 8); for a point on the surface (within ``CONTACT``),
        where that direction is rounding, the pseudo-normal there; for a point on the
        target's medial axis (``tied``), the mean of the gradients towards its two closest
        points. Zero for
        vertices that do not contribute.
    signed : (n,) float64 signed distance ``d_j`` to the target, positive outside; for
        a point that ``known`` proves inside, a negative upper bound of it.
    """
    if mode not in ("inside", "nearest"):
        raise ValueError(f"unknown packaging mode {mode!r}")
    X = np.asarray(X, dtype=np.float64)
    signed = np.empty(len(X))
    gradient = np.zeros_like(X)
    if known is None or mode != "inside":
        query = np.arange(len(X))
        near = target.closest(X)
    else:
        query = known.undecided(X)
        near = known.closest(target, X, query)
        signed[:] = known.bound(X)
    signed[query] = near.signed
    touch = CONTACT * target.diagonal
    offset = X[query] - near.point
    length = np.abs(near.signed)
    off_surface = length > touch
    direction = near.normal.copy()
    direction[off_surface] = (offset[off_surface] * (np.sign(near.signed[off_surface])
                                                     / length[off_surface])[:, None])
    # on the medial axis: the mean of the gradients towards the two closest points
    tied = near.tied & off_surface
    direction[tied] = 0.5 * (direction[tied] + (X[query][tied] - near.other_point[tied])
                             * (np.sign(near.signed[tied]) / length[tied])[:, None])
    if mode == "inside":
        # a point on the surface (within the contact tolerance) is not outside: its last
        # bits would otherwise decide whether it pulls, and in which direction
        active = signed > touch
        value = float(signed[active].sum())
        weight = (near.signed > touch).astype(np.float64)
    else:
        value = float(length.sum())
        weight = np.sign(near.signed)
    gradient[query] = direction * weight[:, None]
    return value, gradient, signed


class InsideBounds:
    """Points proven inside a target since their last closest-point query, and the answers
    of the points that have not moved since.

    The signed distance is 1-Lipschitz: a point at signed distance ``d < 0`` when it was
    last queried, moved by ``m`` since, has ``d' <= d + m``, so while ``d + m < -slack``
    it is still inside, and the inside packaging response (value and gradient zero
    there) does not need its closest point. Points that are outside or near the surface
    are queried every time, but for those at the very coordinates of their last query,
    which keep its answer (:meth:`closest`; a point's answer does not depend on the other
    query points): the result is the same as querying all of them.

    With ``depth > 0`` the points proven deeper than ``depth`` are skipped (the pull inside,
    :func:`core.fitting.best_fit.pull_inside`, leaves them free).

    Parameters
    ----------
    slack : float >= 0, model units; a bound above ``-(depth + slack)`` counts as undecided
        (keeps rounding of the moves from deciding a point on the threshold).
    depth : float >= 0, model units.
    """

    def __init__(self, slack, depth=0.0):
        self.slack = float(slack)
        self.depth = float(depth)
        self.points = None
        self.signed = None
        self.answers = None
        self.answered = None

    def bound(self, X):
        """(n,) float64 upper bounds of the signed distances of ``X`` ((n, 3))."""
        return self.signed + np.linalg.norm(X - self.points, axis=1)

    def undecided(self, X):
        """(k,) int64 indices of the points of ``X`` ((n, 3)) to query."""
        if self.points is None or len(self.points) != len(X):
            self.points = self.signed = self.answers = self.answered = None
            return np.arange(len(X))
        return np.flatnonzero(self.bound(X) >= -(self.depth + self.slack))

    def closest(self, target, X, query):
        """The closest points (:meth:`core.target_surface.TargetSurface.closest`) of
        ``X[query]`` (``X`` (n, 3), ``query`` (k,) int64), recorded; the points at the
        coordinates of their last query keep its answer, the others are queried.

        Returns
        -------
        core.target_surface.ClosestPoints of the ``k`` points.
        """
        fresh = query
        if self.answers is not None and len(self.points) == len(X):
            kept = self.answered[query] & (X[query] == self.points[query]).all(axis=1)
            fresh = query[~kept]
        self.record(X, fresh, target.closest(X[fresh]))
        return ClosestPoints(**{name: rows[query] for name, rows in self.answers.items()})

    def record(self, X, query, near):
        """Keep the answers ``near`` (ClosestPoints of ``X[query]``, ``query`` (k,) int64)."""
        if self.points is None or len(self.points) != len(X):
            self.points, self.signed = np.array(X, dtype=np.float64), np.zeros(len(X))
            self.answers = {item.name: np.zeros((len(X),) + getattr(near, item.name).shape[1:],
                                                dtype=getattr(near, item.name).dtype)
                            for item in fields(near)}
            self.answered = np.zeros(len(X), dtype=bool)
        self.points[query] = X[query]
        self.signed[query] = near.signed
        for name, rows in self.answers.items():
            rows[query] = getattr(near, name)
        self.answered[query] = True


def vertex_normals(X, T):
    """(n, 3) float64 unit area-weighted vertex normals (the volume gradient's direction)."""
    face_normal = face_cross(X, T)
    summed = scatter_add(T.T.reshape(-1), np.tile(face_normal, (3, 1)), len(X))
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    return np.divide(summed, length, out=np.zeros_like(summed), where=length > 0)


@dataclass
class Thickness:
    """Ray-cast wall thickness of a closed triangle mesh at its vertices.

    thickness : (n,) float64 distance along ``-normal`` to the first exit through the
        surface; ``max_length`` where no exit is found within ``max_length``.
    hit_face : (n,) int64 triangle hit, ``-1`` where none.
    hit_bary : (n, 3) float64 barycentric coordinates of the hit on ``hit_face``.
    normal : (n, 3) float64 unit vertex normals used as ray directions (negated).
    slope : (n,) float64 ``1 / (d . m)`` with ``d`` the ray and ``m`` the hit
        triangle's unit normal (0 where no hit).
    hit_normal : (n, 3) float64 unit normal ``m`` of the hit triangle.
    """

    thickness: np.ndarray
    hit_face: np.ndarray
    hit_bary: np.ndarray
    normal: np.ndarray
    slope: np.ndarray
    hit_normal: np.ndarray


def thickness(X, T, max_length):
    """Distance from every vertex along its inward normal to the other side (Eq. 9).

    A ray leaves each vertex along ``-n_j`` (area-weighted vertex normal); the first
    triangle it exits through (hit with ``d . m > 0``, ``m`` the triangle's outward
    normal, at a distance ``> core.tolerances.CONTACT * max_length``) ends it. The triangles of the
    vertex's own one-ring are entered, not exited, so they never count. The rays are
    cast by :meth:`core.target_surface.TargetSurface.first_exit` (compiled, with an
    exact float64 check and a tolerant re-cast of rays through edges and vertices).

    Parameters
    ----------
    X : (n, 3) float64
    T : (t, 3) int64
    max_length : float > 0, ray length (model units); thicker walls report it.

    Returns
    -------
    Thickness
    """
    normal = vertex_normals(X, T)
    direction = -normal
    hits = TargetSurface(X, T, "fitted surface").first_exit(X, direction, max_length)
    hit = hits.face >= 0
    value = np.where(hit, hits.t, max_length)
    slope = np.zeros(len(X))
    slope[hit] = 1.0 / np.einsum("ij,ij->i", direction[hit], hits.normal[hit])
    return Thickness(value, hits.face, hits.bary, normal, slope, hits.normal)


def thickness_gradient(X, T, result):
    """Sparse derivatives of every vertex thickness with respect to the vertices.

    For vertex ``j`` with hit point ``Y = sum_k b_k X_{T[f, k]}`` on triangle ``f``
    (unit normal ``m``), ``t_j = (Y - X_j) . m / (d . m)`` with the ray direction
    ``d`` and ``m`` held fixed: ``d t_j / d X_j = -m / (d . m)`` and
    ``d t_j / d X_{T[f, k]} = b_k m / (d . m)`` (exact for translations of the hit
    triangle; the change of ``d`` and ``m`` with the vertices is neglected, as in the
    paper's Eq. 9). Vertices without a hit have zero gradient.

    Returns
    -------
    rows : (p,) int64 vertex whose thickness the entry belongs to.
    cols : (p,) int64 vertex the derivative is taken with respect to.
    vals : (p, 3) float64 derivative vectors.
    """
    hit = np.flatnonzero(result.hit_face >= 0)
    g = result.hit_normal[hit] * result.slope[hit, None]
    corners = T[result.hit_face[hit]]
    rows = np.concatenate([hit] + [hit] * 3)
    cols = np.concatenate([hit] + [corners[:, k] for k in range(3)])
    vals = np.concatenate([-g] + [g * result.hit_bary[hit, k, None] for k in range(3)])
    return rows, cols, vals


def thickness_constraint(X, T, t_min, rho=50.0, max_factor=2.0):
    """Aggregated thickness constraint ``g <= 0`` for ``t_j >= t_min`` at all vertices.

    ``g = KS(x) = max(x) + log(sum exp(rho (x_j - max(x)))) / rho`` with
    ``x_j = (t_min - t_j) / t_min`` (Kreisselmeier-Steinhauser), a smooth upper bound
    of the worst relative violation that exceeds it by at most ``log(n) / rho``.
    Rays are cast ``max_factor * t_min`` far; thicker walls count as that.

    Parameters
    ----------
    X : (n, 3) float64
    T : (t, 3) int64
    t_min : float > 0, model units.
    rho : float > 0
    max_factor : float > 1

    Returns
    -------
    value : float, dimensionless (negative when every vertex is thick enough).
    gradient : (n, 3) float64, ``d value / d X``.
    min_thickness : float, smallest vertex thickness found (model units).
    """
    result = thickness(X, T, max_factor * t_min)
    x = (t_min - result.thickness) / t_min
    top = x.max()
    w = np.exp(rho * (x - top))
    value = float(top + np.log(w.sum()) / rho)
    weight = w / w.sum() / -t_min
    rows, cols, vals = thickness_gradient(X, T, result)
    grad = scatter_add(cols, vals * weight[rows, None], len(X))
    return value, grad, float(result.thickness.min())

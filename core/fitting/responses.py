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
from dataclasses import dataclass
from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

_RAY_BLOCK = 200000
_EDGE_TOL = 1e-9


def triangulate(face_vertices, face_offsets):
    """Fan triangulation of a CSR polygon mesh.

    Parameters
    ----------
    face_vertices : (k,) int64
    face_offsets : (m + 1,) int64

    Returns
    -------
    (t, 3) int64 triangles ``(c0, c_j, c_{j+1})`` of every face, same orientation; quads
    give ``(0, 1, 2), (0, 2, 3)``.
    """
    fv = np.asarray(face_vertices, dtype=np.int64)
    fo = np.asarray(face_offsets, dtype=np.int64)
    sizes = np.diff(fo)
    count = np.maximum(sizes - 2, 0)
    face = np.repeat(np.arange(len(sizes)), count)
    j = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + 1
    start = fo[face]
    return np.stack([fv[start], fv[start + j], fv[start + j + 1]], axis=1)


def volume(X, T):
    """Enclosed volume (Eq. 7) and its exact gradient.

    Returns
    -------
    value : float, model units cubed (positive for an outward-oriented closed mesh).
    gradient : (n, 3) float64, ``d value / d X``; for vertex ``j`` it equals
        ``1/6 * sum over triangles (j, b, c) of X_b x X_c`` = one third of the
        area-weighted normal of its one-ring.
    """
    a, b, c = X[T[:, 0]], X[T[:, 1]], X[T[:, 2]]
    value = float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0
    grad = np.zeros_like(X)
    for corner, (p, q) in enumerate(((b, c), (c, a), (a, b))):
        np.add.at(grad, T[:, corner], np.cross(p, q) / 6.0)
    return value, grad


def packaging(X, target, mode="inside"):
    """Packaging response (Eq. 8) against a :class:`TargetSurface`.

    Parameters
    ----------
    X : (n, 3) float64
    target : core.fitting.closest_point.TargetSurface
    mode : ``'inside'`` sums ``max(d_j, 0)`` (penetration out of the target, the
        paper's form); ``'nearest'`` sums ``|d_j|``.

    Returns
    -------
    value : float, model units.
    gradient : (n, 3) float64. With the closest point inside a target face it is the
        face normal (Eq. 8); on an edge or a vertex of the target it is the exact
        gradient of the distance, ``(X_j - CPP_j) / |X_j - CPP_j|``, signed. Zero for
        vertices that do not contribute.
    signed : (n,) float64 signed distance ``d_j`` to the target, positive outside.
    """
    signed, closest, _, normal, region = target.signed_distance(X)
    offset = X - closest
    length = np.abs(signed)
    direction = np.divide(offset, length[:, None], out=normal.copy(),
                          where=(region[:, None] != 0) & (length[:, None] > 0))
    direction[region != 0] *= np.sign(signed[region != 0])[:, None]
    if mode == "inside":
        active = signed > 0
        value = float(signed[active].sum())
        weight = active.astype(np.float64)
    elif mode == "nearest":
        value = float(length.sum())
        weight = np.sign(signed)
    else:
        raise ValueError(f"unknown packaging mode {mode!r}")
    return value, direction * weight[:, None], signed


def vertex_normals(X, T):
    """(n, 3) float64 unit area-weighted vertex normals (the volume gradient's direction)."""
    a, b, c = X[T[:, 0]], X[T[:, 1]], X[T[:, 2]]
    face_normal = np.cross(b - a, c - a)
    summed = np.zeros_like(X)
    for corner in range(3):
        np.add.at(summed, T[:, corner], face_normal)
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
    normal, at a distance ``> 1e-9 * max_length``) ends it. The triangles of the
    vertex's own one-ring are entered, not exited, so they never count. Broad phase:
    a cKDTree over triangle centroids returns the triangles whose bounding sphere can
    meet the segment ``[X_j, X_j - max_length n_j]``; the Moeller-Trumbore test runs
    on those pairs, vectorised.

    Parameters
    ----------
    X : (n, 3) float64
    T : (t, 3) int64
    max_length : float > 0, ray length (model units); thicker walls report it.

    Returns
    -------
    Thickness
    """
    n = len(X)
    normal = vertex_normals(X, T)
    direction = -normal
    tri = X[T]
    centroid = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centroid[:, None], axis=2).max(axis=1)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    face_normal = np.cross(e1, e2)
    face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-300)
    cand, owner = _ray_candidates(X + 0.5 * max_length * direction, 0.5 * max_length,
                                  centroid, radius)
    best = np.full(n, np.inf)
    best_face = np.full(n, -1, dtype=np.int64)
    best_uv = np.zeros((n, 2))
    for start in range(0, len(cand), _RAY_BLOCK):
        f, o = cand[start:start + _RAY_BLOCK], owner[start:start + _RAY_BLOCK]
        t, u, v, ok = _ray_triangle(X[o], direction[o], tri[f, 0], e1[f], e2[f])
        ok &= np.einsum("ij,ij->i", direction[o], face_normal[f]) > 0
        ok &= (t > 1e-9 * max_length) & (t <= max_length)
        f, o, t, u, v = f[ok], o[ok], t[ok], u[ok], v[ok]
        if not len(o):
            continue
        order = np.lexsort((t, o))
        first = order[np.flatnonzero(np.r_[True, o[order][1:] != o[order][:-1]])]
        take = t[first] < best[o[first]]
        who = o[first][take]
        best[who] = t[first][take]
        best_face[who] = f[first][take]
        best_uv[who] = np.stack([u[first][take], v[first][take]], axis=1)
    hit = best_face >= 0
    value = np.where(hit, best, max_length)
    bary = np.zeros((n, 3))
    bary[hit] = np.stack([1 - best_uv[hit].sum(axis=1), best_uv[hit, 0], best_uv[hit, 1]],
                         axis=1)
    hit_normal = np.zeros((n, 3))
    hit_normal[hit] = face_normal[best_face[hit]]
    slope = np.zeros(n)
    slope[hit] = 1.0 / np.einsum("ij,ij->i", direction[hit], hit_normal[hit])
    return Thickness(value, best_face, bary, normal, slope, hit_normal)


def _ray_candidates(centre, reach, centroid, radius):
    """Triangles whose bounding sphere meets the sphere ``(centre_j, reach)`` of each ray.

    Triangles are split at the 90th percentile of their bounding radius; each class gets
    its own k-d tree searched with its own largest radius, so a few large triangles do
    not widen the search for all.

    Returns
    -------
    candidates : (p,) int64 triangle ids; owners : (p,) int64 ray ids.
    """
    split = float(np.quantile(radius, 0.9))
    found_t, found_o = [], []
    for members in (np.flatnonzero(radius <= split), np.flatnonzero(radius > split)):
        if not len(members):
            continue
        lists = cKDTree(centroid[members]).query_ball_point(
            centre, r=reach + float(radius[members].max()))
        lengths = np.fromiter(map(len, lists), np.int64, len(centre))
        if lengths.sum():
            found_t.append(members[np.fromiter(chain.from_iterable(lists), np.int64,
                                               int(lengths.sum()))])
            found_o.append(np.repeat(np.arange(len(centre)), lengths))
    if not found_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(found_t), np.concatenate(found_o)


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
    grad = np.zeros_like(X)
    np.add.at(grad, cols, vals * weight[rows, None])
    return value, grad, float(result.thickness.min())


def _ray_triangle(origin, direction, a, e1, e2):
    """Moeller-Trumbore on row-wise pairs; returns (t, u, v, hit) arrays of length p."""
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-300
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origin - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", direction, q) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    # a small tolerance so rays through an edge or a vertex hit one of its triangles
    ok &= (u >= -_EDGE_TOL) & (v >= -_EDGE_TOL) & (u + v <= 1 + _EDGE_TOL)
    return t, u, v, ok

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Point location among planar triangles (2D), vectorised.

Used to find, for a point on a polycube chart, the deformed triangle it lies in and its
barycentric coordinates there, so the same combination of the original vertices maps the
point back onto the target surface.
"""
import numpy as np
from scipy.spatial import cKDTree

NEAREST_CANDIDATES = 16
"""Triangles (nearest centroids) tested per point before the exhaustive fallback."""
CHUNK = 4_000_000
"""Point-triangle pairs tested at once in the exhaustive fallback (memory bound)."""


def barycentric_2d(points, tri):
    """Barycentric coordinates of points in triangles.

    Parameters
    ----------
    points : (q, 2) float64 query points.
    tri : (q, 3, 2) float64 triangle corners (any orientation, non-degenerate).

    Returns
    -------
    (q, 3) float64 barycentric coordinates (sum 1; all >= 0 inside).
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2, d = b - a, c - a, points - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(det == 0.0, 1e-300, det)
    l1 = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
    l2 = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=1)


def _score(points, tri, flipped, tolerance):
    """Rank of candidate triangles: inside and not flipped > inside and flipped > outside.

    Within a class the larger smallest barycentric coordinate wins. Inside non-flipped
    scores are >= 2 - tolerance, inside flipped >= 1 - tolerance, outside in (-1, 0).
    """
    low = barycentric_2d(points, tri).min(axis=1)
    inside = low >= -tolerance
    outside = low / (1.0 + np.abs(low))
    return np.where(inside, np.where(flipped, 1.0, 2.0) + low, outside)


def locate_points(points, tri, flipped, tolerance):
    """Triangle containing each point, preferring non-flipped triangles.

    Parameters
    ----------
    points : (q, 2) float64 query points.
    tri : (t, 3, 2) float64 non-degenerate triangles (t >= 1).
    flipped : (t,) bool triangles to use only when no other triangle contains the point.
    tolerance : float >= 0, a point counts as inside when its smallest barycentric
        coordinate is >= -tolerance.

    Returns
    -------
    index : (q,) int64 chosen triangle; points in no triangle get the one with the largest
        smallest barycentric coordinate (nearest in that sense), and ``inside`` False.
    bary : (q, 3) float64 barycentric coordinates in it, clipped to the triangle.
    inside : (q,) bool point lies in the chosen triangle (within ``tolerance``).
    """
    q, t = len(points), len(tri)
    index = np.zeros(q, dtype=np.int64)
    best = np.full(q, -np.inf)
    if q == 0:
        return index, np.zeros((0, 3)), np.zeros(0, dtype=bool)
    tree = cKDTree(tri.mean(axis=1))
    k = min(NEAREST_CANDIDATES, t)
    _, cand = tree.query(points, k=k)
    cand = np.asarray(cand, dtype=np.int64).reshape(q, k)
    for j in range(k):
        score = _score(points, tri[cand[:, j]], flipped[cand[:, j]], tolerance)
        better = score > best
        index[better], best[better] = cand[better, j], score[better]
    # points not inside a non-flipped candidate: test every triangle, in chunks
    todo = np.flatnonzero(best < 2.0 - tolerance)
    step = max(1, CHUNK // t)
    for start in range(0, len(todo), step):
        pts = todo[start:start + step]
        pp = np.repeat(points[pts], t, axis=0)
        tt = np.tile(np.arange(t), len(pts))
        score = _score(pp, tri[tt], flipped[tt], tolerance)
        score = score.reshape(len(pts), t)
        arg = np.argmax(score, axis=1)
        top = score[np.arange(len(pts)), arg]
        better = top > best[pts]
        index[pts[better]], best[pts[better]] = arg[better], top[better]
    bary = barycentric_2d(points, tri[index])
    low = bary.min(axis=1)
    inside = low >= -tolerance
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    return index, bary, inside


def winding_numbers(points, start, end):
    """Winding number of closed oriented 2D edge sets around points (crossing rule).

    Parameters
    ----------
    points : (q, 2) float64 query points (not on an edge).
    start, end : (e, 2) float64 edge end points; the edges form closed loops.

    Returns
    -------
    (q,) int64 winding numbers (counter-clockwise loops count +1).
    """
    q, e = len(points), len(start)
    out = np.zeros(q, dtype=np.int64)
    if q == 0 or e == 0:
        return out
    step = max(1, CHUNK // e)
    for s in range(0, q, step):
        p = points[s:s + step, None, :]
        a, b = start[None], end[None]
        side = ((b[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1])
                - (p[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1]))
        up = (a[..., 1] <= p[..., 1]) & (b[..., 1] > p[..., 1]) & (side > 0)
        down = (b[..., 1] <= p[..., 1]) & (a[..., 1] > p[..., 1]) & (side < 0)
        out[s:s + step] = up.sum(axis=1) - down.sum(axis=1)
    return out

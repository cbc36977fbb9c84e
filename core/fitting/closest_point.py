# SPDX-License-Identifier: LGPL-2.1-or-later
"""Exact, vectorised closest-point queries on a fixed triangle mesh (the fit target).

:class:`TargetSurface` builds its search structure once (scipy cKDTrees over triangle
centroids, one per class of triangle sizes) and answers any number of queries, so the
shape optimisation reuses it in every iteration.

Broad phase: an upper bound ``U`` on the distance comes from the few triangles whose
centroids are nearest; a triangle with centroid ``c`` and bounding radius ``r`` can
only be closer if ``|q - c| <= U + r``, so each size class's tree is searched with
radius ``U + r_class``; candidates are pruned again with the exact lower bound
``max(|q - c| - r, |distance to the triangle's plane|)`` and the rest are tested
exactly (Ericson's Voronoi-region closest point on a triangle).

The normal returned at the closest point is the angle-weighted pseudo-normal
(Baerentzen and Aanaes 2005): the face normal when the closest point is inside a
face, the mean of the two face normals on an edge, the angle-weighted vertex normal
at a vertex. With it the sign of ``(q - closest) . normal`` is the exact inside /
outside sign of ``q`` for a closed, outward-oriented target.
"""
from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

from core.geometry import radius_classes
from core.quality import validate_triangles

_NEAREST = 8
_BLOCK = 4096

REGION_FACE = 0
# region codes 1, 2, 3: edges (v0 v1), (v1 v2), (v2 v0); 4, 5, 6: vertices v0, v1, v2


def closest_on_triangles(triangles, points):
    """Closest point on ``triangles[i]`` to ``points[i]`` (Ericson's region test).

    Parameters
    ----------
    triangles : (k, 3, 3) float64, corners ``a, b, c``.
    points : (k, 3) float64

    Returns
    -------
    closest : (k, 3) float64
    bary : (k, 3) float64 barycentric coordinates of ``closest`` (sum 1).
    region : (k,) int8, 0 face interior, 1..3 edges ab, bc, ca, 4..6 corners a, b, c.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    ap, bp, cp = points - a, points - b, points - c
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    k = len(points)
    v = np.zeros(k)
    w = np.zeros(k)
    region = np.full(k, -1, dtype=np.int8)

    def claim(mask, code, vv, ww):
        take = mask & (region < 0)
        region[take] = code
        v[take] = vv[take] if np.ndim(vv) else vv
        w[take] = ww[take] if np.ndim(ww) else ww

    with np.errstate(divide="ignore", invalid="ignore"):
        claim((d1 <= 0) & (d2 <= 0), 4, 0.0, 0.0)
        claim((d3 >= 0) & (d4 <= d3), 5, 1.0, 0.0)
        claim((vc <= 0) & (d1 >= 0) & (d3 <= 0), 1, d1 / (d1 - d3), 0.0)
        claim((d6 >= 0) & (d5 <= d6), 6, 0.0, 1.0)
        claim((vb <= 0) & (d2 >= 0) & (d6 <= 0), 3, 0.0, d2 / (d2 - d6))
        e = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        claim((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), 2, 1.0 - e, e)
        denom = va + vb + vc
        safe = np.where(denom != 0, denom, 1.0)
        claim(np.ones(k, dtype=bool), REGION_FACE, vb / safe, vc / safe)
    closest = a + v[:, None] * ab + w[:, None] * ac
    bary = np.stack([1.0 - v - w, v, w], axis=1)
    return closest, bary, region


class TargetSurface:
    """Search structure over a closed triangle mesh for repeated closest-point queries.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, counter-clockwise seen from outside.

    Attributes
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    face_normals : (m, 3) float64 unit outward normals (zero for degenerate faces).
    diagonal : float, bounding-box diagonal (model units).
    """

    def __init__(self, vertices, faces):
        V, F = validate_triangles(vertices, faces, "target")
        self.vertices, self.faces = V, F
        tri = V[F]
        self._tri = tri
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(cross, axis=1)
        self.face_normals = np.divide(cross, length[:, None], out=np.zeros_like(cross),
                                      where=length[:, None] > 0)
        self.diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
        self._centroids = tri.mean(axis=1)
        self._radius = np.linalg.norm(tri - self._centroids[:, None], axis=2).max(axis=1)
        self._nearest = cKDTree(self._centroids)
        self._classes = [(members, cKDTree(self._centroids[members]),
                          float(self._radius[members].max()))
                         for members in radius_classes(self._radius)]
        self._edge_normals, self._vertex_normals = self._pseudo_normals()

    def _pseudo_normals(self):
        """(m, 3, 3) per face-edge and (n, 3) per vertex unit pseudo-normals."""
        F, V, fn = self.faces, self.vertices, self.face_normals
        pairs = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
        _, edge_id = np.unique(np.sort(pairs, axis=1), axis=0, return_inverse=True)
        edge_id = edge_id.reshape(-1)
        summed = np.zeros((edge_id.max() + 1, 3))
        np.add.at(summed, edge_id, np.repeat(fn, 3, axis=0))
        edge_normals = _unit(summed)[edge_id].reshape(-1, 3, 3)
        tri = self._tri
        angles = np.empty((len(F), 3))
        for corner in range(3):
            e1 = tri[:, (corner + 1) % 3] - tri[:, corner]
            e2 = tri[:, (corner + 2) % 3] - tri[:, corner]
            cosine = np.einsum("ij,ij->i", _unit(e1), _unit(e2))
            angles[:, corner] = np.arccos(np.clip(cosine, -1.0, 1.0))
        vertex_sum = np.zeros_like(V)
        np.add.at(vertex_sum, F.reshape(-1), (angles[:, :, None] * fn[:, None, :]).reshape(-1, 3))
        return edge_normals, _unit(vertex_sum)

    def query(self, points):
        """Closest points on the target.

        Parameters
        ----------
        points : (k, 3) float

        Returns
        -------
        closest : (k, 3) float64 closest points on the target surface.
        face : (k,) int64 target face containing each closest point.
        normal : (k, 3) float64 unit pseudo-normal at the closest point (the face
            normal when the point is inside the face).
        region : (k,) int8 where on the face the closest point lies (see
            :func:`closest_on_triangles`).
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        k = len(points)
        face = np.empty(k, dtype=np.int64)
        for start in range(0, k, _BLOCK):
            face[start:start + _BLOCK] = self._nearest_faces(points[start:start + _BLOCK])
        closest, _, region = closest_on_triangles(self._tri[face], points)
        return closest, face, self._normal_at(face, region), region

    def signed_distance(self, points):
        """(k,) float64 signed distances, positive outside the target; plus query results."""
        closest, face, normal, region = self.query(points)
        offset = np.asarray(points, dtype=np.float64).reshape(-1, 3) - closest
        distance = np.linalg.norm(offset, axis=1)
        sign = np.where(np.einsum("ij,ij->i", offset, normal) >= 0, 1.0, -1.0)
        return sign * distance, closest, face, normal, region

    def _normal_at(self, face, region):
        normal = self.face_normals[face].copy()
        on_edge = (region >= 1) & (region <= 3)
        normal[on_edge] = self._edge_normals[face[on_edge], region[on_edge] - 1]
        on_vertex = region >= 4
        corner = self.faces[face[on_vertex], region[on_vertex] - 4]
        normal[on_vertex] = self._vertex_normals[corner]
        return normal

    def _nearest_faces(self, block):
        """(b,) int64 face nearest to each point of a block (exact)."""
        n = len(block)
        k = min(_NEAREST, len(self.faces))
        _, near = self._nearest.query(block, k=k)
        near = near.reshape(n, k)
        owner = np.repeat(np.arange(n), k)
        dist = _distances(self._tri[near.ravel()], block[owner]).reshape(n, k)
        pick = dist.argmin(axis=1)
        best = dist[np.arange(n), pick]
        best_face = near[np.arange(n), pick]
        for members, tree, class_radius in self._classes:
            lists = tree.query_ball_point(block, r=best + class_radius)
            lengths = np.fromiter(map(len, lists), np.int64, n)
            if not lengths.any():
                continue
            candidates = members[np.fromiter(chain.from_iterable(lists), np.int64,
                                             lengths.sum())]
            owner = np.repeat(np.arange(n), lengths)
            offset = block[owner] - self._centroids[candidates]
            lower = np.maximum(
                np.linalg.norm(offset, axis=1) - self._radius[candidates],
                np.abs(np.einsum("ij,ij->i", offset, self.face_normals[candidates])))
            keep = lower < best[owner]
            candidates, owner = candidates[keep], owner[keep]
            if not len(owner):
                continue
            dist = _distances(self._tri[candidates], block[owner])
            order = np.lexsort((dist, owner))
            owner, candidates, dist = owner[order], candidates[order], dist[order]
            first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
            who, d, f = owner[first], dist[first], candidates[first]
            better = d < best[who]
            best[who[better]] = d[better]
            best_face[who[better]] = f[better]
        return best_face


def _distances(triangles, points):
    closest, _, _ = closest_on_triangles(triangles, points)
    return np.linalg.norm(closest - points, axis=1)


def _unit(x):
    length = np.linalg.norm(x, axis=1, keepdims=True)
    return np.divide(x, length, out=np.zeros_like(x), where=length > 0)

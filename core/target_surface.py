# SPDX-License-Identifier: LGPL-2.1-or-later
"""One compiled spatial-query object per closed triangle mesh: closest points, signed
distances with pseudo-normals, and first exits of rays.

:class:`TargetSurface` builds the compiled trees of :mod:`core.box_tree` once (on the
first query of each kind) and answers any number of queries; the fit (packaging response),
the thickness rays and the quality check's surface distances all use it.

Closest points: the tree returns the nearest triangle of every query point; the point,
its barycentric coordinates and where on the triangle it lies (face, edge or corner)
are then recomputed exactly in float64 on that triangle (Ericson's Voronoi-region
test). The normal at the closest point is the angle-weighted pseudo-normal (Baerentzen
and Aanaes 2005): the face normal inside a face, the mean of the two face normals on an
edge, the angle-weighted vertex normal at a corner; with it the sign of
``(q - closest) . normal`` is the exact inside / outside sign of ``q`` for a closed,
outward-oriented mesh. The normal returned takes a closest point within ``CONTACT`` of an
edge or corner as on it, so that points on the target's feature lines get the same normal
whatever their last bits; the sign is still the exact one. A query point on the surface's
medial axis is as near to two places (the two walls of a thin member); the answer names the
other one too (``tied``), so that the fit's rows can use both rather than the one rounding
picked (:meth:`ClosestPoints.mean_plane`). With ``split=True`` the tree holds the long triangles cut into shorter
pieces (``SPLIT_EDGE``), each numbered back to its triangle, so a query opens fewer boxes;
the answers are still computed on the mesh's own triangles.

Rays (:meth:`TargetSurface.first_exit`): the compiled cast tests every triangle it reaches
in float64 with a barycentric tolerance of ``EDGE_TOL``, so a ray through an edge or a
vertex hits one of its triangles.
"""
import hashlib
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from core.box_tree import (closest_on_triangles, first_exits, nearest_triangles,
                           rival_triangles, triangle_tree)
from core.geometry import (bisect_long_triangles, morton_codes, sample_surface, scatter_add,
                           unit_face_normals, validate_triangles)
from core.tolerances import CONTACT

EDGE_TOL = 1e-9
"""Barycentric tolerance of the exact ray-triangle test (dimensionless)."""
RAY_BOX_PAD = 1e-8
"""The triangles' boxes of the ray cast are widened by this much of the diagonal, more than
the hits ``EDGE_TOL`` admits outside a triangle and the slab test's rounding."""

SPLIT_EDGE = 2.0
"""With ``split=True``, the search tree holds the triangles cut into pieces no longer than
this many times the median of the triangles' longest edges
(:func:`core.geometry.bisect_long_triangles`). A long
triangle's box overlaps those of many short ones, and a query near it opens them all;
cut into pieces, the closest-point queries of the fit on a CAD-like target with long
triangles take about half the time. Meshes without long triangles are unchanged."""
SPLIT_MOST = 4
"""... and at most this many times as many pieces as triangles: while more, the longest
piece allowed is doubled."""
TIE_ANGLE = np.radians(8.0)
"""Two closest points of a query point are two places (the point is tied between them,
:attr:`ClosestPoints.tied`) when the directions from the point to them differ by more than
this; the triangles around one closest point, and coplanar ones just beyond it, are within
a fraction of it."""
ORDERED_QUERIES = 64
"""Queries of at least this many points are searched in Z-order (:func:`_search_order`);
fewer points are searched as given, since coding and sorting them costs more than the shared
tree walks save (most of a one-point query's time)."""
CLOSEST_KEPT = 4
"""Most answers of :meth:`TargetSurface.closest` kept (the latest), each for its query
points bit for bit, and as many of :meth:`TargetSurface.samples_nearest`: the fit queries
some point sets again (a refit starts where the fit before it ended, the inside pull where
the untangled fit is; a query on a fine target is costly). Two
already find those; 16 found only a few more small ones (the cold refits' first coarse
rounds), at four times the memory (an answer and its points: about 120 bytes a point)."""


@dataclass
class NearestPoints:
    """Closest points on a :class:`TargetSurface` to ``k`` query points, unsigned.

    point : (k, 3) float64 closest points on the surface.
    face : (k,) int64 triangle holding each closest point.
    bary : (k, 3) float64 barycentric coordinates of ``point`` on ``face``.
    region : (k,) int8 where on that triangle: 0 inside, 1..3 edges (v0 v1), (v1 v2),
        (v2 v0), 4..6 corners v0, v1, v2.
    distance : (k,) float64 distance (model units).
    """

    point: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    region: np.ndarray
    distance: np.ndarray


@dataclass
class ClosestPoints(NearestPoints):
    """:class:`NearestPoints` with the pseudo-normal and the inside / outside sign.

    normal : (k, 3) float64 unit pseudo-normal at the closest point.
    signed : (k,) float64 signed distance (model units), positive outside.
    tied : (k,) bool, another place of the surface in another direction is as near (within
        ``CONTACT`` of the diagonal): the query point lies on the surface's medial axis
        (midway between the walls of a thin member, on the bisector of a concave corner),
        and which of the two ``point`` is was decided by rounding.
    other_point, other_normal : (k, 3) float64, that other closest point and its
        pseudo-normal where ``tied``; ``point`` and ``normal`` elsewhere.
    """

    normal: np.ndarray = None
    signed: np.ndarray = None
    tied: np.ndarray = None
    other_point: np.ndarray = None
    other_normal: np.ndarray = None

    def mean_plane(self):
        """The tangent plane of each answer, averaged over its two closest points where it is
        tied: ``(normal, offset)``, (k, 3) and (k,) float64, the plane
        ``normal . x = offset`` (``normal`` shorter than one where tied: the mean of two unit
        normals). A point-to-plane row built on it is the mean of the rows of the two closest
        points, so it does not depend on which of them rounding picked; elsewhere it is the
        plane of the pseudo-normal at the closest point, bit for bit.
        """
        normal = 0.5 * (self.normal + self.other_normal)
        offset = 0.5 * (np.einsum("ij,ij->i", self.normal, self.point)
                        + np.einsum("ij,ij->i", self.other_normal, self.other_point))
        return normal, offset


@dataclass
class RayHits:
    """First exits of ``k`` rays through a :class:`TargetSurface`.

    t : (k,) float64 distance along the (unit) ray to the exit; ``inf`` where none.
    face : (k,) int64 triangle exited through, ``-1`` where none.
    bary : (k, 3) float64 barycentric coordinates of the exit on ``face`` (zeros where none).
    normal : (k, 3) float64 unit outward normal of ``face`` (zeros where none).
    """

    t: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    normal: np.ndarray


class TargetSurface:
    """Compiled closest-point and ray queries on a fixed closed triangle mesh.

    Parameters
    ----------
    vertices : (n, 3) float, model units.
    faces : (m, 3) int, counter-clockwise seen from outside.
    name : str, what to call the mesh in error messages.
    split : bool, search among pieces of the long triangles (``SPLIT_EDGE``); the answers
        are still computed on the mesh's own triangles, but where two triangles are equally
        near (at a shared edge or corner) the one returned may differ from the unsplit
        tree's, and the point with it in the last bits.

    Attributes
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    face_normals : (m, 3) float64 unit outward normals (zero for degenerate faces).
    diagonal : float, bounding-box diagonal (model units).

    Raises
    ------
    InvalidMeshError
        Malformed arrays (see :func:`core.geometry.validate_triangles`).
    """

    def __init__(self, vertices, faces, name="target", split=False):
        V, F = validate_triangles(vertices, faces, name)
        self.vertices, self.faces = V, F
        self._tri = V[F]
        self.face_normals = unit_face_normals(V, F)
        self.diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
        # the closest points' tree mesh: the triangles, or pieces of them numbered back by
        # _piece_face
        self._tree_mesh, self._piece_face = (V, F), None
        if split:
            pieces = _pieces(V, F, self._tri)
            if pieces is not None:
                self._tree_mesh, self._piece_face = pieces[:2], pieces[2]
        self._samples = {}
        self._kept = OrderedDict()
        self._kept_samples = OrderedDict()

    def nearest(self, points):
        """Closest points and unsigned distances (no pseudo-normals).

        Parameters
        ----------
        points : (k, 3) float, model units.

        Returns
        -------
        NearestPoints
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        face = np.zeros(len(points), dtype=np.int64)
        if len(points):
            order = _search_order(points)
            face[order] = self._triangle_of(nearest_triangles(self._point_tree, points[order]))
        point, bary, region = closest_on_triangles(self._tri[face], points)
        return NearestPoints(point, face, bary, region, np.linalg.norm(points - point, axis=1))

    def closest(self, points):
        """Closest points, pseudo-normals and signed distances.

        Parameters
        ----------
        points : (k, 3) float, model units.

        Returns
        -------
        ClosestPoints, its arrays read only: the answer to the same points (bit for bit)
            among the last ``CLOSEST_KEPT`` queries is returned again, not recomputed; of
            a query of as many points as the latest kept one, only the points that differ
            from that one's are computed (:meth:`_closest_of_changed`).
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        return _kept_or_new(self._kept, (points,), lambda: self._closest_of_changed(points))

    def _closest_of_changed(self, points):
        """:meth:`_closest` of ``points``, the rows at the coordinates of the same rows of the
        latest kept query of as many points copied from its answer.

        A point's answer does not depend on the other query points, so the result is the
        same bit for bit; cages that differ from one in a few moved vertices (the base
        mesh's repairs) ask for the same face centres again but for a few.
        """
        if self._kept:
            (previous,), answer = next(reversed(self._kept.values()))
            if previous.shape == points.shape:
                # compared bit for bit (0.0 and -0.0 differ)
                fresh = np.flatnonzero((previous.view(np.int64) != points.view(np.int64))
                                       .any(axis=1))
                if len(fresh) < len(points):
                    rows = {name: np.array(value) for name, value in vars(answer).items()}
                    for name, value in vars(self._closest(points[fresh])).items():
                        rows[name][fresh] = value
                    return ClosestPoints(**rows)
        return self._closest(points)

    def _closest(self, points):
        """:meth:`closest`, computed."""
        near = self.nearest(points)
        # the sign from the exact region's normal: it is the exact inside / outside sign
        exact = self._normal_at(near.face, near.region)
        sign = np.where(np.einsum("ij,ij->i", points - near.point, exact) >= 0, 1.0, -1.0)
        normal = self._normal_at(near.face, self._snapped_region(near.face, near.region,
                                                                 near.bary))
        other_point, other_normal = near.point.copy(), normal.copy()
        rival = self._rivals(points, near)
        tied = rival >= 0
        if tied.any():
            point, bary, region = closest_on_triangles(self._tri[rival[tied]], points[tied])
            other_point[tied] = point
            other_normal[tied] = self._normal_at(rival[tied], self._snapped_region(
                rival[tied], region, bary))
        return ClosestPoints(near.point, near.face, near.bary, near.region, near.distance,
                             normal, sign * near.distance, tied, other_point, other_normal)

    def _rivals(self, points, near):
        """(k,) int64 the triangle of each point's rival closest point
        (:func:`core.box_tree.rival_triangles`, within ``CONTACT`` of the diagonal and more
        than ``TIE_ANGLE`` away in direction), ``-1`` where none."""
        rival = np.full(len(points), -1, dtype=np.int64)
        if len(points):
            order = _search_order(points)
            rival[order] = self._triangle_of(rival_triangles(
                self._point_tree, points[order], near.point[order], near.distance[order],
                CONTACT * self.diagonal, np.cos(TIE_ANGLE)))
        return rival

    def samples_nearest(self, vertices, faces, count, seed=0):
        """Closest points on another triangle mesh to this surface's samples (:meth:`samples`).

        The least-squares fit's backward term asks this of its fitted limit surface every
        round (:func:`core.fitting.best_fit.best_fit`), and a refit's first round asks it
        again of the surface the fit before it ended with.

        Parameters
        ----------
        vertices : (n, 3) float; faces : (m, 3) int, the other mesh (model units).
        count, seed : int, which samples (:meth:`samples`).

        Returns
        -------
        near : NearestPoints of the ``count`` samples on the other mesh.
        normals : (count, 3) float64 unit normals of the other mesh's triangles holding them.
            Both read only: the answer to the same mesh (bit for bit) and samples among the
            last ``CLOSEST_KEPT`` such queries is returned again, not recomputed.
        """
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.ascontiguousarray(faces)
        points, _ = self.samples(count, seed)

        def compute():
            other = TargetSurface(vertices, faces, "fitted surface")
            near = other.nearest(points)
            return near, other.face_normals[near.face]

        return _kept_or_new(self._kept_samples, (vertices, faces, np.array([count, seed])),
                            compute)

    def first_exit(self, origins, directions, max_length):
        """Where rays starting inside (or on) the surface first leave the solid.

        A hit counts if the ray crosses a triangle from inside to outside (``d . m > 0``,
        ``m`` its outward normal) at ``CONTACT * max_length < t <= max_length``
        (:data:`core.tolerances.CONTACT`), so the triangles around a ray's own start vertex,
        which it enters, never count (:func:`core.box_tree.first_exits`, barycentric
        tolerance ``EDGE_TOL``).

        Parameters
        ----------
        origins : (k, 3) float, model units.
        directions : (k, 3) float, unit vectors.
        max_length : float > 0, ray length (model units).

        Returns
        -------
        RayHits
        """
        origins = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
        directions = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        t, face, uv = first_exits(self._ray_tree, self.face_normals, origins, directions,
                                  max_length, CONTACT * max_length, EDGE_TOL)
        found = face >= 0
        bary = np.zeros((len(origins), 3))
        bary[found] = np.stack([1.0 - uv[found].sum(axis=1), uv[found, 0], uv[found, 1]], axis=1)
        normal = np.zeros((len(origins), 3))
        normal[found] = self.face_normals[face[found]]
        return RayHits(t, face, bary, normal)

    def samples(self, count, seed=0):
        """Area-weighted random points on the surface and the pseudo-normals there.

        Drawn once per ``(count, seed)`` (:func:`core.geometry.sample_surface` with
        ``numpy.random.default_rng(seed)``) and kept: every least-squares fit on this
        target uses the same samples.

        Returns
        -------
        points : (count, 3) float64, model units.
        normals : (count, 3) float64 unit pseudo-normals at them.
        """
        key = (int(count), int(seed))
        if key not in self._samples:
            points = sample_surface(self.vertices, self.faces, key[0],
                                    np.random.default_rng(key[1]))
            self._samples[key] = (points, self.closest(points).normal)
        return self._samples[key]

    def _triangle_of(self, found):
        """(k,) int64 the triangles of the tree's answers ``found`` ((k,) int64, ``-1`` kept)."""
        if self._piece_face is None:
            return found
        return np.where(found >= 0, self._piece_face[np.maximum(found, 0)], -1)

    @cached_property
    def _ray_tree(self):
        """The tree over the triangles for rays (:func:`core.box_tree.triangle_tree`)."""
        return triangle_tree(self._tri, RAY_BOX_PAD * self.diagonal)

    @cached_property
    def _point_tree(self):
        """The tree over the closest points' tree mesh (the ray tree when not split)."""
        if self._piece_face is None:
            return self._ray_tree
        V, F = self._tree_mesh
        return triangle_tree(V[F], RAY_BOX_PAD * self.diagonal)

    @cached_property
    def _pseudo_normals(self):
        """(m, 3, 3) per face-edge and (n, 3) per vertex unit pseudo-normals."""
        F, V, fn = self.faces, self.vertices, self.face_normals
        pairs = np.sort(np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
        _, edge_id = np.unique(pairs[:, 0] * len(V) + pairs[:, 1], return_inverse=True)
        edge_id = edge_id.reshape(-1)
        summed = scatter_add(edge_id, np.repeat(fn, 3, axis=0), edge_id.max() + 1)
        edge_normals = _unit(summed)[edge_id].reshape(-1, 3, 3)
        tri = self._tri
        e1 = _unit(np.roll(tri, -1, axis=1) - tri)
        e2 = _unit(np.roll(tri, -2, axis=1) - tri)
        angles = np.arccos(np.clip(np.einsum("ijk,ijk->ij", e1, e2), -1.0, 1.0))
        weighted = (angles[:, :, None] * fn[:, None, :]).reshape(-1, 3)
        vertex_sum = scatter_add(F.reshape(-1), weighted, len(V))
        return edge_normals, _unit(vertex_sum)

    @cached_property
    def _heights(self):
        """(m, 3) float64 distance of each face's corner ``i`` from the opposite edge's line
        (model units; zero for a degenerate face)."""
        tri = self._tri
        twice_area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                    axis=1)
        opposite = np.linalg.norm(np.roll(tri, -2, axis=1) - np.roll(tri, -1, axis=1), axis=2)
        return np.divide(twice_area[:, None], opposite, out=np.zeros_like(opposite),
                         where=opposite > 0)

    def _snapped_region(self, face, region, bary):
        """``region`` with a closest point within ``CONTACT`` of the diagonal of an edge (of
        two edges: their corner) moved onto that edge (corner).

        A point on a feature line of the target (a fitted crease curve, a limit point held
        on an edge) would otherwise take the normal of whichever triangle the last bits of
        its coordinates fall on: a face normal on one machine, the edge's mean normal on
        another, and a fit row that uses it turns by up to 90 degrees.

        Parameters
        ----------
        face : (k,) int64; region : (k,) int8 codes of :class:`NearestPoints`;
        bary : (k, 3) float64 barycentric coordinates on ``face``.

        Returns
        -------
        (k,) int8 region codes; a region is only ever raised from face to edge or corner,
        from edge to corner.
        """
        near = bary * self._heights[face] <= CONTACT * self.diagonal  # (k, 3)
        count = near.sum(axis=1)
        snapped = np.array(region, dtype=np.int8)
        # near the edge opposite corner i: edge codes 1..3 are (v0 v1), (v1 v2), (v2 v0)
        one = (count == 1) & (snapped == 0)
        snapped[one] = np.array([2, 3, 1], dtype=np.int8)[np.argmax(near[one], axis=1)]
        # near two edges: the corner they share (the one coordinate not near zero); a
        # degenerate face near all three: its corner of the largest coordinate
        corner = np.where(count == 2, np.argmin(near, axis=1), np.argmax(bary, axis=1))
        many = (count >= 2) & (snapped < 4)
        snapped[many] = 4 + corner[many]
        return snapped

    def _normal_at(self, face, region):
        edge_normals, vertex_normals = self._pseudo_normals
        normal = self.face_normals[face].copy()
        on_edge = (region >= 1) & (region <= 3)
        normal[on_edge] = edge_normals[face[on_edge], region[on_edge] - 1]
        on_vertex = region >= 4
        normal[on_vertex] = vertex_normals[self.faces[face[on_vertex], region[on_vertex] - 4]]
        return normal


def _pieces(V, F, tri):
    """The pieces of :func:`core.geometry.bisect_long_triangles` for ``SPLIT_EDGE`` times the
    median of the triangles' longest edges and ``SPLIT_MOST`` (``tri`` = ``V[F]``), or None
    when no triangle is cut.

    The longest edge allowed is doubled while ``sum (e / longest)^2`` over the triangles
    longer than it (``e`` a triangle's longest edge; about the pieces a well-shaped triangle
    is cut into) is above the pieces allowed.
    """
    side = np.roll(tri, -1, axis=1) - tri
    squared = np.einsum("ijk,ijk->ij", side, side).max(axis=1)
    longest = SPLIT_EDGE * float(np.sqrt(np.median(squared)))
    most = SPLIT_MOST * len(F)
    while longest > 0:
        long = squared > longest ** 2
        if not long.any():
            return None
        if len(F) + float(np.sum(squared[long])) / longest ** 2 <= most:
            pieces = bisect_long_triangles(V, F, longest, most)
            if pieces is not None:
                return pieces if len(pieces[1]) > len(F) else None
        longest *= 2.0
    return None


def _unit(x):
    """``x`` scaled to unit length along its last axis (the coordinates); zero rows stay zero."""
    length = np.linalg.norm(x, axis=-1, keepdims=True)
    return np.divide(x, length, out=np.zeros_like(x), where=length > 0)


def _kept_or_new(kept, arrays, compute):
    """The answer of ``compute()`` for the query given by ``arrays`` (tuple of arrays), kept.

    ``kept`` (OrderedDict, oldest first) maps a digest of the arrays to them and their
    answer (an object of read-only arrays or a tuple of them); the answer to the same arrays
    (bit for bit) is returned again, a new one is computed, made read only and kept, and
    only the latest ``CLOSEST_KEPT`` stay.
    """
    digest = hashlib.blake2b(digest_size=16)
    for array in arrays:
        digest.update(repr((array.dtype.str, array.shape)).encode())
        digest.update(array.tobytes())
    key = digest.digest()
    found = kept.get(key)
    if found is not None and all(np.array_equal(a, b) for a, b in zip(found[0], arrays)):
        kept.move_to_end(key)
        return found[1]
    answer = compute()
    for part in answer if isinstance(answer, tuple) else (answer,):
        for array in (part,) if isinstance(part, np.ndarray) else vars(part).values():
            array.setflags(write=False)
    kept[key] = (tuple(array.copy() for array in arrays), answer)
    if len(kept) > CLOSEST_KEPT:
        kept.popitem(last=False)
    return answer


def _search_order(points):
    """(k,) int64 the order to search ``points`` ((k, 3) float64) in: Z-order for a query of
    at least :data:`ORDERED_QUERIES` points (neighbouring queries then walk the same tree
    nodes, which is faster than scattered order), as given for fewer. Each point's answer
    does not depend on the order."""
    if len(points) < ORDERED_QUERIES:
        return np.arange(len(points))
    return np.argsort(morton_codes(points), kind="stable")

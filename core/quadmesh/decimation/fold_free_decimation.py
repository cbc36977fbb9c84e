# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quadric-error decimation whose triangles never fold against the target.

QSlim (:mod:`core.quadmesh.decimation.decimation`, libigl's ``igl.qslim``) refuses only the
collapses that change the topology. On a topology-optimisation result of high genus, decimated to a
few hundred or thousand triangles, many of its triangles then span a thin strut or plate: their
corners lie on opposite sides of the member, their normal is across the target's, and the quads
paired of them fold over themselves, so the Catmull-Clark limit surface of the cage crosses itself
next to them however it is fitted. This decimation collapses edges in the same quadric-error order
(Garland & Heckbert, "Surface simplification using quadric error metrics", SIGGRAPH 1997;
area-weighted plane quadrics, the cost of a collapse the summed quadric at the kept vertex) but as
half-edge collapses, so every vertex left is a vertex of the target with a known target normal, and
it refuses a collapse that

* breaks the link condition (the two ends share exactly the two opposite vertices), so the
  topology and genus stay the target's;
* makes a triangle whose unit normal has a cosine below :data:`MIN_NORMAL_COSINE` with the
  (smoothed, :data:`NORMAL_SMOOTHING`) target normal at any of its corners: a triangle across
  a strut has corners whose normals point away from each other, and no such triangle can
  agree with all of them;
* turns a triangle's normal by more than ``arccos`` :data:`MIN_FLIP_COSINE`, or leaves it
  thinner than :data:`MIN_QUALITY` (or, when it was already, than :data:`QUALITY_KEPT` of that);
* gives the kept vertex more than :data:`MAX_FACES` triangles.

A cage paired of it can still cross itself where a member is thinner than its triangles are
long: :meth:`FoldFreeDecimation.tightened` asks a closer normal agreement of the target
vertices collapsed into the crossing faces, so the decimation keeps more triangles only there.

Started with a smallest normal cosine of -1 (no normal rule), the same collapses make a
half-edge QSlim that reaches any count; :meth:`FoldFreeDecimation.tightened` then brings in the
normal rule only around the crossings of its cage, so the cage gets more faces only there
(:mod:`core.quadmesh.decimation.paired_decimation`, step 3).

A refused collapse is tried again when the neighbourhood of one of its ends changes. The
collapses run compiled (numba), about a second for 50k triangles; where every collapse left is
refused, the result keeps more triangles than asked for (the caller's face count grows and
says why).
"""
import heapq

import numpy as np

from core.compiled import keeps_interrupts, numba
from core.errors import InvalidMeshError
from core.mesh_topology import connected_face_components, edge_faces, genus_of

MIN_NORMAL_COSINE = 0.2
"""A collapse is refused when it makes a triangle whose normal is more than about 78 degrees
from the target normal at one of its corners."""
MIN_FLIP_COSINE = 0.7
"""A collapse is refused when it turns a triangle's normal by more than about 45 degrees: a
larger turn in one collapse is how a triangle comes to lie across a member (each step agreeing
with the normals at its corners, the triangle swinging over the strut's side)."""
MIN_QUALITY = 0.2
"""Triangle quality ``4 sqrt(3) area / (sum of squared edge lengths)`` (1 for an equilateral
triangle) below which a collapse is refused, unless the triangle was already thinner and keeps
:data:`QUALITY_KEPT` of its quality."""
QUALITY_KEPT = 0.9
"""Share of its quality a triangle already thinner than :data:`MIN_QUALITY` may lose."""
MAX_FACES = 24
"""Most triangles around one vertex: a collapse that gives its kept vertex more is refused
(valences above a dozen give the paired cage pinched limit surfaces)."""
TIGHTEN_STEP = 0.2
"""Raise of the smallest normal cosine per :meth:`FoldFreeDecimation.tightened`."""
MOST_NORMAL_COSINE = 0.8
"""The smallest normal cosine is raised to at most this (about 37 degrees)."""
NORMAL_SMOOTHING = 2
"""Rounds of averaging of the target's vertex normals with those of their neighbours: the
normals of an unsmoothed marching-cubes surface point along the voxel axes; two rounds give
the direction of the surface the staircase approximates without mixing the normals of the two
sides of a member a few voxels thick."""


class FoldFreeDecimation:
    """Fold-free decimations (module docstring) of one closed, outward 2-manifold target.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 the target.
    min_normal_cosine : float, the smallest cosine asked of every target vertex at first:
        :data:`MIN_NORMAL_COSINE`, or -1 for no normal rule until :meth:`tightened`.

    Attributes
    ----------
    min_normal_cosine : (n,) float64 the smallest cosine asked of every target vertex.
    tightenings : int, the :meth:`tightened` calls this decimation comes of.
    fold_free : bool, every vertex asks at least :data:`MIN_NORMAL_COSINE` (the start did).

    Raises
    ------
    InvalidMeshError (from :meth:`triangles`) when a decimation changed the genus: collapses
    that would are refused, so this means a defect in the input the intake did not catch.
    """

    def __init__(self, vertices, faces, min_normal_cosine=MIN_NORMAL_COSINE):
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self._faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._components = int(connected_face_components(self._faces).max()) + 1
        self._genus = genus_of(len(self._vertices), self._faces, self._components)
        self._normals = smoothed_vertex_normals(self._vertices, self._faces, NORMAL_SMOOTHING)
        self._quadrics = plane_quadrics(self._vertices, self._faces)
        self._edges = edge_faces(self._faces)[0]
        self.min_normal_cosine = np.full(len(self._vertices), float(min_normal_cosine))
        self.fold_free = bool(min_normal_cosine >= MIN_NORMAL_COSINE)
        self.tightenings = 0
        self._results = {}
        self._results_detail = {}

    def tightened(self, count, points):
        """A decimation that keeps more triangles around ``points``.

        The vertices of the decimation to ``count`` triangles closest to ``points`` ((k, 3)
        float64, e.g. the corners of cage faces whose limit surface crosses itself), and
        their neighbours there, are found; every target vertex collapsed into one of them
        gets its smallest normal cosine raised by :data:`TIGHTEN_STEP`, and to at least
        :data:`MIN_NORMAL_COSINE` (at most :data:`MOST_NORMAL_COSINE`), so the triangles
        there must agree more closely with the target's normals and fewer collapses are
        allowed there. Returns a new
        FoldFreeDecimation (None when no vertex there can be tightened further).
        """
        from scipy.spatial import cKDTree

        vertices, faces = self.triangles(count)
        used, cluster = self._results_detail[len(faces)]
        hit = np.unique(cKDTree(vertices).query(np.asarray(points, dtype=np.float64))[1])
        ring = np.zeros(len(vertices), dtype=bool)
        ring[hit] = True
        ring[faces[ring[faces].any(axis=1)].reshape(-1)] = True
        region = ring[cluster]
        raised = np.where(region, np.minimum(np.maximum(self.min_normal_cosine + TIGHTEN_STEP,
                                                        MIN_NORMAL_COSINE), MOST_NORMAL_COSINE),
                          self.min_normal_cosine)
        if np.array_equal(raised, self.min_normal_cosine):
            return None
        other = object.__new__(FoldFreeDecimation)
        other.__dict__.update(self.__dict__)
        other.min_normal_cosine = raised
        other.tightenings = self.tightenings + 1
        other._results = {}
        other._results_detail = {}
        return other

    def triangles(self, count):
        """The decimation to at most ``count`` triangles, or more where every collapse left is
        refused (the target itself when it has no more than ``count``).

        Returns ``(vertices, faces)``: (n', 3) float64 vertices of the target and (m', 3)
        int64 faces, closed, outward, the target's genus. The same count gives the same
        (cached) arrays, and so does every count below the triangles of a decimation that
        stopped short of its count.
        """
        count = int(count)
        if count >= len(self._faces):
            return self._vertices, self._faces
        floor = min((result for wanted, result in self._results.items()
                     if len(result[1]) > wanted), key=lambda result: len(result[1]),
                    default=None)
        if floor is not None and count < len(floor[1]):
            # the collapses run in a fixed order, so a count below a result that stopped
            # short (every collapse left refused) ends at the same refusals
            return floor
        if count not in self._results:
            faces, alive, parent = keeps_interrupts(_collapse)(
                self._vertices, self._faces.copy(), self._normals, self._quadrics.copy(),
                self._edges, count, self.min_normal_cosine, MIN_FLIP_COSINE, MIN_QUALITY,
                QUALITY_KEPT, MAX_FACES)
            faces = faces[alive]
            used = np.unique(faces)
            renumber = np.full(len(self._vertices), -1, dtype=np.int64)
            renumber[used] = np.arange(len(used))
            vertices, faces = self._vertices[used], renumber[faces]
            if genus_of(len(vertices), faces, self._components) != self._genus:
                raise InvalidMeshError("the decimated target changed its genus; the input "
                                       "surface is not a clean 2-manifold")
            while True:  # every target vertex's last representative, a vertex left
                following = parent[parent]
                if np.array_equal(following, parent):
                    break
                parent = following
            self._results[count] = (vertices, faces)
            self._results_detail[len(faces)] = (used, renumber[parent])
        return self._results[count]


def folded_share(vertices, faces, decimated_vertices, decimated_faces):
    """Share of a decimation's triangles that face across the target: a cosine below 0 between
    the triangle's normal and the smoothed target normal (:data:`NORMAL_SMOOTHING`) at the
    target vertex closest to one of its corners (a float in [0, 1]).

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 the target.
    decimated_vertices : (n', 3) float64; decimated_faces : (m', 3) int64 its decimation.
    """
    from scipy.spatial import cKDTree

    if not len(decimated_faces):
        return 0.0
    normals = smoothed_vertex_normals(vertices, faces, NORMAL_SMOOTHING)
    nearest = cKDTree(vertices).query(decimated_vertices)[1]
    P = decimated_vertices
    cross = _unit(np.cross(P[decimated_faces[:, 1]] - P[decimated_faces[:, 0]],
                           P[decimated_faces[:, 2]] - P[decimated_faces[:, 0]]))
    cosine = np.einsum("fkj,fj->fk", normals[nearest][decimated_faces], cross)
    return float((cosine.min(axis=1) < 0.0).mean())


def smoothed_vertex_normals(vertices, faces, rounds):
    """(n, 3) float64 unit area-weighted vertex normals averaged ``rounds`` times with their
    edge neighbours' (uniform weights)."""
    import scipy.sparse as sp

    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                     vertices[faces[:, 2]] - vertices[faces[:, 0]])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], cross)
    n = len(vertices)
    rows = faces.reshape(-1)
    cols = np.roll(faces, -1, axis=1).reshape(-1)
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    adjacency = adjacency + adjacency.T + sp.identity(n)
    normals = _unit(normals)
    for _ in range(rounds):
        normals = _unit(adjacency @ normals)
    return np.ascontiguousarray(normals)


def plane_quadrics(vertices, faces):
    """(n, 10) float64 area-weighted plane quadric of every vertex, the upper triangle of the
    symmetric 4x4 matrix (``a a, a b, a c, a d, b b, b c, b d, c c, c d, d d``)."""
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                     vertices[faces[:, 2]] - vertices[faces[:, 0]])
    twice_area = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(twice_area, 1e-300)[:, None]
    plane = np.concatenate([normal, -np.einsum("ij,ij->i", normal, vertices[faces[:, 0]])[:, None]],
                           axis=1)
    upper = np.triu_indices(4)
    face_quadric = 0.5 * twice_area[:, None] * (plane[:, upper[0]] * plane[:, upper[1]])
    quadrics = np.zeros((len(vertices), 10))
    for k in range(3):
        np.add.at(quadrics, faces[:, k], face_quadric)
    return quadrics


def _unit(x):
    return x / np.maximum(np.linalg.norm(x, axis=1), 1e-300)[:, None]


@numba.njit(cache=True, nogil=True)
def _quadric_error(Q, a, b, V, p):
    """Error of vertex ``p``'s position in the summed quadric of vertices ``a`` and ``b``."""
    x, y, z = V[p, 0], V[p, 1], V[p, 2]
    terms = (x * x, 2.0 * x * y, 2.0 * x * z, 2.0 * x, y * y, 2.0 * y * z, 2.0 * y, z * z,
             2.0 * z, 1.0)
    error = 0.0
    for i in range(10):
        error += (Q[a, i] + Q[b, i]) * terms[i]
    return error


@numba.njit(cache=True, nogil=True)
def _ring(v, F, vf, nvf, out):
    """Number of distinct neighbours of ``v`` written to ``out``."""
    count = 0
    for i in range(nvf[v]):
        f = vf[v, i]
        for k in range(3):
            w = F[f, k]
            if w == v:
                continue
            seen = False
            for j in range(count):
                if out[j] == w:
                    seen = True
                    break
            if not seen:
                out[count] = w
                count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _normal_quality(V, a, b, c):
    """Unit normal ``(x, y, z)`` (zeros when degenerate) and quality of the triangle of
    vertices ``a b c``."""
    ux, uy, uz = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
    wx, wy, wz = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
    vx, vy, vz = V[c, 0] - V[b, 0], V[c, 1] - V[b, 1], V[c, 2] - V[b, 2]
    nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    twice_area = np.sqrt(nx * nx + ny * ny + nz * nz)
    squares = (ux * ux + uy * uy + uz * uz + wx * wx + wy * wy + wz * wz
               + vx * vx + vy * vy + vz * vz)
    quality = 2.0 * np.sqrt(3.0) * twice_area / max(squares, 1e-300)
    if twice_area > 0.0:
        nx, ny, nz = nx / twice_area, ny / twice_area, nz / twice_area
    return nx, ny, nz, quality


@numba.njit(cache=True, nogil=True)
def _allowed(u, v, V, F, vf, nvf, N, ring_u, ring_v, min_normal, min_flip, min_quality,
             quality_kept, max_faces):
    """Whether the half-edge collapse of ``u`` into ``v`` is allowed (module docstring)."""
    shared = 0
    for i in range(nvf[u]):
        f = vf[u, i]
        if F[f, 0] == v or F[f, 1] == v or F[f, 2] == v:
            shared += 1
    if shared != 2:
        return False
    if nvf[u] + nvf[v] - 4 > max_faces:
        return False
    nu = _ring(u, F, vf, nvf, ring_u)
    nv = _ring(v, F, vf, nvf, ring_v)
    common = 0
    for i in range(nu):
        for j in range(nv):
            if ring_u[i] == ring_v[j]:
                common += 1
    if common != 2:
        return False
    for i in range(nvf[u]):
        f = vf[u, i]
        if F[f, 0] == v or F[f, 1] == v or F[f, 2] == v:
            continue
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        ox, oy, oz, old_q = _normal_quality(V, a, b, c)
        if a == u:
            a = v
        elif b == u:
            b = v
        else:
            c = v
        nx, ny, nz, new_q = _normal_quality(V, a, b, c)
        if new_q <= 0.0 or nx * ox + ny * oy + nz * oz < min_flip:
            return False
        if new_q < min_quality and new_q < quality_kept * old_q:
            return False
        for w in (a, b, c):
            if nx * N[w, 0] + ny * N[w, 1] + nz * N[w, 2] < min_normal[w]:
                return False
    return True


@numba.njit(cache=True, nogil=True)
def _push_edges(w, F, vf, nvf, Q, V, stamp, heap, counter, ring):
    """Queue both half-edge collapses of every edge of ``w``; returns the new counter."""
    nw = _ring(w, F, vf, nvf, ring)
    for j in range(nw):
        x = ring[j]
        heapq.heappush(heap, (_quadric_error(Q, w, x, V, x), counter, w, x, stamp[w], stamp[x]))
        counter += 1
        heapq.heappush(heap, (_quadric_error(Q, w, x, V, w), counter, x, w, stamp[x], stamp[w]))
        counter += 1
    return counter


@numba.njit(cache=True, nogil=True)
def _collapse(V, F, N, Q, edges, count, min_normal, min_flip, min_quality, quality_kept,
              max_faces):
    """Half-edge collapses in quadric-error order down to ``count`` triangles.

    Returns ``(F, alive, parent)``: the faces with collapsed vertices renamed, which are
    left, and the vertex each vertex was collapsed into (itself if it is left).
    """
    n, m = len(V), len(F)
    cap = 4 * max_faces
    vf = np.full((n, cap), -1, dtype=np.int64)
    nvf = np.zeros(n, dtype=np.int64)
    for f in range(m):
        for k in range(3):
            v = F[f, k]
            if nvf[v] < cap:
                vf[v, nvf[v]] = f
            nvf[v] += 1
    alive = np.ones(m, dtype=np.bool_)
    parent = np.arange(n)
    if nvf.max() > cap:
        return F, alive, parent  # a vertex with too many triangles: left as it is
    stamp = np.zeros(n, dtype=np.int64)
    refused = np.zeros(n, dtype=np.bool_)
    ring_u = np.empty(cap, dtype=np.int64)
    ring_v = np.empty(cap, dtype=np.int64)
    ring = np.empty(cap, dtype=np.int64)
    heap = [(0.0, 0, 0, 0, 0, 0)]
    heap.pop()
    counter = 0
    for e in range(len(edges)):
        a, b = edges[e, 0], edges[e, 1]
        heap.append((_quadric_error(Q, a, b, V, b), counter, a, b, 0, 0))
        heap.append((_quadric_error(Q, a, b, V, a), counter + 1, b, a, 0, 0))
        counter += 2
    heapq.heapify(heap)
    faces_left = m
    while faces_left > count and len(heap):
        _, _, u, v, su, sv = heapq.heappop(heap)
        if stamp[u] != su or stamp[v] != sv or stamp[u] < 0 or stamp[v] < 0:
            continue
        if not _allowed(u, v, V, F, vf, nvf, N, ring_u, ring_v, min_normal, min_flip,
                        min_quality, quality_kept, max_faces):
            refused[u] = True
            refused[v] = True
            continue
        # the two shared triangles go; u's other triangles pass to v
        for i in range(nvf[u]):
            f = vf[u, i]
            if F[f, 0] == v or F[f, 1] == v or F[f, 2] == v:
                alive[f] = False
                faces_left -= 1
                for k in range(3):
                    w = F[f, k]
                    if w == u:
                        continue
                    j = 0
                    while vf[w, j] != f:
                        j += 1
                    vf[w, j] = vf[w, nvf[w] - 1]
                    nvf[w] -= 1
        for i in range(nvf[u]):
            f = vf[u, i]
            if not alive[f]:
                continue
            for k in range(3):
                if F[f, k] == u:
                    F[f, k] = v
            vf[v, nvf[v]] = f
            nvf[v] += 1
        nvf[u] = 0
        parent[u] = v
        Q[v] += Q[u]
        stamp[u] = -1
        stamp[v] += 1
        nv = _ring(v, F, vf, nvf, ring_v)
        counter = _push_edges(v, F, vf, nvf, Q, V, stamp, heap, counter, ring)
        for j in range(nv):
            w = ring_v[j]
            if refused[w]:
                refused[w] = False
                counter = _push_edges(w, F, vf, nvf, Q, V, stamp, heap, counter, ring)
    return F, alive, parent

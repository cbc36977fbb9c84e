# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quadric-error decimation whose triangles never fold against the target.

QSlim (:mod:`core.quadmesh.decimation`, libigl's ``igl.qslim``) refuses only the collapses that
change the topology. On a topology-optimisation result of high genus, decimated to a few
hundred or thousand triangles, many of its triangles then span a thin strut or plate: their
corners lie on opposite sides of the member, their normal is across the target's, and the
quads paired of them fold over themselves, so the Catmull-Clark limit surface of the cage
crosses itself next to them however it is fitted. This decimation collapses edges in the same
quadric-error order (Garland & Heckbert, "Surface simplification using quadric error
metrics", SIGGRAPH 1997; area-weighted plane quadrics, the cost of a collapse the summed
quadric at the kept vertex) but as half-edge collapses, so every vertex left is a vertex of the
target with a known target normal, and it refuses a collapse that

* breaks the link condition (the two ends share exactly the two opposite vertices), so the
  topology and genus stay the target's;
* makes a triangle whose unit normal has a cosine below :data:`MIN_NORMAL_COSINE` with the
  (smoothed, :data:`NORMAL_SMOOTHING`) target normal at any of its corners: a triangle across
  a strut has corners whose normals point away from each other, and no such triangle can
  agree with all of them;
* turns a triangle's normal by more than ``arccos`` :data:`MIN_FLIP_COSINE`, or leaves it
  thinner than :data:`MIN_QUALITY` (or, when it was already, than :data:`QUALITY_KEPT` of that);
* gives the kept vertex more than :data:`MAX_FACES` triangles.

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

    Raises
    ------
    InvalidMeshError (from :meth:`triangles`) when a decimation changed the genus: collapses
    that would are refused, so this means a defect in the input the intake did not catch.
    """

    def __init__(self, vertices, faces):
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self._faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._components = int(connected_face_components(self._faces).max()) + 1
        self._genus = genus_of(len(self._vertices), self._faces, self._components)
        self._normals = smoothed_vertex_normals(self._vertices, self._faces, NORMAL_SMOOTHING)
        self._quadrics = plane_quadrics(self._vertices, self._faces)
        self._edges = edge_faces(self._faces)[0]
        self._results = {}

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
            faces, alive = keeps_interrupts(_collapse)(self._vertices, self._faces.copy(), self._normals,
                                     self._quadrics.copy(), self._edges, count,
                                     MIN_NORMAL_COSINE, MIN_FLIP_COSINE, MIN_QUALITY,
                                     QUALITY_KEPT, MAX_FACES)
            faces = faces[alive]
            used = np.unique(faces)
            renumber = np.full(len(self._vertices), -1, dtype=np.int64)
            renumber[used] = np.arange(len(used))
            vertices, faces = self._vertices[used], renumber[faces]
            if genus_of(len(vertices), faces, self._components) != self._genus:
                raise InvalidMeshError("the decimated target changed its genus; the input "
                                       "surface is not a clean 2-manifold")
            self._results[count] = (vertices, faces)
        return self._results[count]


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
def _quadric_error(q, p):
    x, y, z = p[0], p[1], p[2]
    return (q[0] * x * x + 2.0 * q[1] * x * y + 2.0 * q[2] * x * z + 2.0 * q[3] * x
            + q[4] * y * y + 2.0 * q[5] * y * z + 2.0 * q[6] * y + q[7] * z * z
            + 2.0 * q[8] * z + q[9])


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
def _normal_quality(a, b, c):
    """Unit normal (zeros when degenerate) and quality of triangle ``a b c``."""
    u = b - a
    w = c - a
    n = np.empty(3)
    n[0] = u[1] * w[2] - u[2] * w[1]
    n[1] = u[2] * w[0] - u[0] * w[2]
    n[2] = u[0] * w[1] - u[1] * w[0]
    twice_area = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    squares = (u * u).sum() + (w * w).sum() + ((c - b) * (c - b)).sum()
    quality = 2.0 * np.sqrt(3.0) * twice_area / max(squares, 1e-300)
    if twice_area > 0.0:
        n /= twice_area
    return n, quality


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
        old_n, old_q = _normal_quality(V[F[f, 0]], V[F[f, 1]], V[F[f, 2]])
        corners = np.empty(3, dtype=np.int64)
        for k in range(3):
            corners[k] = v if F[f, k] == u else F[f, k]
        new_n, new_q = _normal_quality(V[corners[0]], V[corners[1]], V[corners[2]])
        if new_q <= 0.0 or (new_n * old_n).sum() < min_flip:
            return False
        if new_q < min_quality and new_q < quality_kept * old_q:
            return False
        for k in range(3):
            if (new_n * N[corners[k]]).sum() < min_normal:
                return False
    return True


@numba.njit(cache=True, nogil=True)
def _push_edges(w, F, vf, nvf, Q, V, stamp, heap, counter, ring):
    """Queue both half-edge collapses of every edge of ``w``; returns the new counter."""
    nw = _ring(w, F, vf, nvf, ring)
    for j in range(nw):
        x = ring[j]
        q = Q[w] + Q[x]
        heapq.heappush(heap, (_quadric_error(q, V[x]), counter, w, x, stamp[w], stamp[x]))
        counter += 1
        heapq.heappush(heap, (_quadric_error(q, V[w]), counter, x, w, stamp[x], stamp[w]))
        counter += 1
    return counter


@numba.njit(cache=True, nogil=True)
def _collapse(V, F, N, Q, edges, count, min_normal, min_flip, min_quality, quality_kept,
              max_faces):
    """Half-edge collapses in quadric-error order down to ``count`` triangles.

    Returns ``(F, alive)``: the faces with collapsed vertices renamed, and which are left.
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
    if nvf.max() > cap:
        return F, alive  # a vertex of the target with too many triangles: left as it is
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
        q = Q[a] + Q[b]
        heap.append((_quadric_error(q, V[b]), counter, a, b, 0, 0))
        heap.append((_quadric_error(q, V[a]), counter + 1, b, a, 0, 0))
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
    return F, alive

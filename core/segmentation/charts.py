# SPDX-License-Identifier: LGPL-2.1-or-later
"""Charts, boundaries and corners of a polycube labeling, as plain arrays.

Definitions (the ones polycube codes use):

- a *chart* is a connected set of faces (through shared edges) with the same part and label;
- a *chart-separating edge* is an edge whose two faces lie in different charts (edges between
  parts are always separating);
- a *corner* is a vertex with three or more chart-separating edges;
- a *boundary* is a maximal chain of separating edges joined at non-corner vertices, i.e. the
  chain between two corners, or a closed loop that passes no corner.

At a non-corner vertex with two separating edges the face fan holds exactly two charts, so every
boundary separates one fixed pair of charts.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from core.compiled import keeps_interrupts, numba
from core.mesh_topology import faces_across, halfedge_faces, unique_edges

OPPOSITE = np.array([1, 0, 3, 2, 5, 4], dtype=np.int64)
"""Label opposite to each label 0..5 (+X <-> -X, +Y <-> -Y, +Z <-> -Z)."""


@dataclass(frozen=True)
class MeshTopology:
    """Edge tables of a closed triangle mesh, computed once and shared by the labeling stages.

    edges : (e, 2) int64 sorted vertex pairs.
    edge_faces : (e, 2) int64 the two faces of each edge (``-1`` where missing).
    face_edges : (m, 3) int64 edge of corner ``k -> k+1`` of each face.
    neighbours : (m, 3) int64 face across edge ``k`` of each face (``-1`` where missing).
    n_vertices : int
    """

    edges: np.ndarray
    edge_faces: np.ndarray
    face_edges: np.ndarray
    neighbours: np.ndarray
    n_vertices: int


def build_topology(F, n_vertices=None):
    """Edge tables of ``F``.

    Parameters
    ----------
    F : (m, 3) int array of vertex indices.
    n_vertices : int, optional; defaults to ``F.max() + 1``.

    Returns
    -------
    MeshTopology
    """
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    edges, he_edge = unique_edges(F)
    edge_faces = halfedge_faces(he_edge, len(edges))
    if n_vertices is None:
        n_vertices = int(F.max()) + 1 if m else 0
    return MeshTopology(edges, edge_faces, he_edge.reshape(m, 3), faces_across(edge_faces, he_edge),
                        int(n_vertices))


@dataclass(frozen=True)
class ChartLayout:
    """Charts, boundaries and corners of one labeling.

    face_chart : (m,) int64 chart of each face.
    chart_label : (c,) int64 label 0..5 of each chart.
    chart_part : (c,) int64 part of each chart.
    chart_size : (c,) int64 number of faces of each chart.
    chart_first_face : (c,) int64 lowest face index of each chart (an example face).
    sep_edges : (k,) int64 indices into ``topology.edges`` of the chart-separating edges.
    sep_boundary : (k,) int64 boundary of each separating edge.
    boundary_charts : (b, 2) int64 the two charts of each boundary (smaller id first).
    boundary_size : (b,) int64 number of edges of each boundary.
    boundary_first_edge : (b,) int64 one edge (index into ``topology.edges``) of each boundary.
    chart_boundary_count : (c,) int64 number of distinct boundaries around each chart.
    chart_neighbours : (c, c) CSR int64, entry = number of boundaries between two charts.
    vertex_sep_degree : (n,) int64 number of separating edges at each vertex.
    corners : (q,) int64 corner vertices, ascending.
    """

    face_chart: np.ndarray
    chart_label: np.ndarray
    chart_part: np.ndarray
    chart_size: np.ndarray
    chart_first_face: np.ndarray
    sep_edges: np.ndarray
    sep_boundary: np.ndarray
    boundary_charts: np.ndarray
    boundary_size: np.ndarray
    boundary_first_edge: np.ndarray
    chart_boundary_count: np.ndarray
    chart_neighbours: sp.csr_matrix
    vertex_sep_degree: np.ndarray
    corners: np.ndarray

    @property
    def n_charts(self):
        return len(self.chart_label)

    @property
    def n_boundaries(self):
        return len(self.boundary_charts)


def find_charts(topology, face_part, face_label):
    """(m,) int64 chart id of each face, ids numbered by lowest face index.

    Parameters
    ----------
    topology : MeshTopology
    face_part, face_label : (m,) int arrays.
    """
    return _charts(topology.edge_faces, np.ascontiguousarray(face_part, dtype=np.int64),
                   np.ascontiguousarray(face_label, dtype=np.int64))


@numba.njit(inline="always")
def _root(parent, x):
    """Root of ``x`` in the union-find forest ``parent``, halving the path on the way."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@numba.njit(inline="always")
def _join(parent, x, y):
    """Merge the sets of ``x`` and ``y`` under the lower root."""
    x, y = _root(parent, x), _root(parent, y)
    if x < y:
        parent[y] = x
    elif y < x:
        parent[x] = y


@numba.njit(inline="always")
def _number_by_first(parent):
    """(n,) int64 set of each node, sets numbered the first time one of their nodes is met in
    node order (so ids follow each set's lowest node)."""
    n = len(parent)
    comp = np.full(n, -1, dtype=np.int64)
    count = 0
    for v in range(n):
        r = _root(parent, v)
        if comp[r] < 0:
            comp[r] = count
            count += 1
        comp[v] = comp[r]
    return comp


@numba.njit(cache=True, nogil=True)
def _charts(edge_faces, face_part, face_label):
    """:func:`find_charts`: faces joined across every edge with two faces of one part and
    label."""
    parent = np.arange(len(face_label))
    for e in range(len(edge_faces)):
        f, g = edge_faces[e, 0], edge_faces[e, 1]
        if f >= 0 and g >= 0 and face_part[f] == face_part[g] and face_label[f] == face_label[g]:
            _join(parent, f, g)
    return _number_by_first(parent)


@numba.njit(cache=True, nogil=True)
def _separating(edge_faces, face_chart):
    """(k,) int64 ascending edges with two faces in different charts."""
    keep = np.zeros(len(edge_faces), dtype=np.bool_)
    for e in range(len(edge_faces)):
        f, g = edge_faces[e, 0], edge_faces[e, 1]
        keep[e] = f >= 0 and g >= 0 and face_chart[f] != face_chart[g]
    return np.flatnonzero(keep)


@numba.njit(cache=True, nogil=True)
def _boundaries(sep_vertices, degree):
    """(k,) int64 boundary of each separating edge (vertex pairs ``sep_vertices``, (k, 2)):
    edges joined at every vertex with exactly two separating edges (``degree`` of each vertex),
    boundaries numbered by lowest edge."""
    k = len(sep_vertices)
    parent = np.arange(k)
    other = np.full(len(degree), -1, dtype=np.int64)
    for i in range(k):
        for end in range(2):
            v = sep_vertices[i, end]
            if degree[v] == 2:
                if other[v] < 0:
                    other[v] = i
                else:
                    _join(parent, other[v], i)
    return _number_by_first(parent)


def _first_index(ids, n):
    """(n,) int64 lowest position of each id 0..n-1 in ``ids`` (every id must occur)."""
    first = np.empty(n, dtype=np.int64)
    first[ids[::-1]] = np.arange(len(ids) - 1, -1, -1)
    return first


@keeps_interrupts
def extract_layout(topology, face_part, face_label):
    """Charts, boundaries and corners of a labeling.

    Parameters
    ----------
    topology : MeshTopology of the mesh.
    face_part : (m,) int part of each face.
    face_label : (m,) int label 0..5 of each face.

    Returns
    -------
    ChartLayout
    """
    face_part = np.ascontiguousarray(face_part, dtype=np.int64)
    face_label = np.ascontiguousarray(face_label, dtype=np.int64)
    m = len(face_label)
    ef = topology.edge_faces
    face_chart = _charts(ef, face_part, face_label)
    n_charts = int(face_chart.max()) + 1 if m else 0
    chart_size = np.bincount(face_chart, minlength=n_charts)
    chart_first = _first_index(face_chart, n_charts)
    chart_label = face_label[chart_first]
    chart_part = face_part[chart_first]

    sep_edges = _separating(ef, face_chart)
    k = len(sep_edges)
    ev = topology.edges[sep_edges]
    n = topology.n_vertices
    degree = np.bincount(ev.reshape(-1), minlength=n)
    sep_boundary = _boundaries(ev, degree)
    n_b = int(sep_boundary.max()) + 1 if k else 0
    first_edge = _first_index(sep_boundary, n_b)
    bc = np.sort(face_chart[ef[sep_edges[first_edge]]], axis=1).reshape(n_b, 2)
    boundary_size = np.bincount(sep_boundary, minlength=n_b)

    chart_boundary_count = np.bincount(bc.reshape(-1), minlength=n_charts)
    corners = np.flatnonzero(degree >= 3)
    return ChartLayout(face_chart, chart_label, chart_part, chart_size, chart_first, sep_edges,
                       sep_boundary, bc, boundary_size, sep_edges[first_edge],
                       chart_boundary_count, _chart_neighbours(bc, n_charts), degree, corners)


def _chart_neighbours(boundary_charts, n_charts):
    """(c, c) CSR int64 number of boundaries between each two charts (both ways), indices
    sorted, from the (b, 2) charts of each boundary."""
    bc = boundary_charts
    key = np.concatenate([bc[:, 0] * n_charts + bc[:, 1], bc[:, 1] * n_charts + bc[:, 0]])
    key, count = np.unique(key, return_counts=True)
    indptr = np.searchsorted(key // n_charts if n_charts else key, np.arange(n_charts + 1))
    return sp.csr_matrix((count.astype(np.int64), key % n_charts if n_charts else key, indptr),
                         shape=(n_charts, n_charts))


@dataclass(frozen=True)
class BoundaryWalks:
    """The walks of :func:`boundary_chains` one after another.

    vertices : int64 vertices of the walks; ``offsets[b] + b`` to ``offsets[b] + b + length[b]``
        (inclusive) the walk of boundary ``b``.
    edges : int64 edges (indices into ``topology.edges``) of the walks; ``offsets[b]`` to
        ``offsets[b] + length[b]`` (exclusive) those of boundary ``b``.
    offsets : (b,) int64; length : (b,) int64 edges walked on each boundary (0 where not walked).
    closed : (b,) bool, True for a boundary without a corner.
    walked : (b,) bool, the boundaries walked.
    """

    vertices: np.ndarray
    edges: np.ndarray
    offsets: np.ndarray
    length: np.ndarray
    closed: np.ndarray
    walked: np.ndarray


@keeps_interrupts
def boundary_walks(topology, layout, which=None):
    """The walks of :func:`boundary_chains` as flat arrays (a :class:`BoundaryWalks`)."""
    n_b = layout.n_boundaries
    walk = np.ones(n_b, dtype=np.bool_) if which is None else np.asarray(which, dtype=np.bool_)
    sep = layout.sep_edges
    chain_v, chain_e, offsets, length, closed = _walk_boundaries(
        topology.edges[sep], layout.vertex_sep_degree, layout.sep_boundary, n_b, walk)
    return BoundaryWalks(chain_v, sep[chain_e], offsets, length, closed, walk)


def boundary_chains(topology, layout, which=None):
    """Ordered vertex chains of every boundary (or of the boundaries flagged in ``which``).

    Parameters
    ----------
    topology : MeshTopology; layout : ChartLayout.
    which : (b,) bool, optional; boundaries not flagged get ``None`` instead of a chain.

    Returns
    -------
    list of (b,) entries; entry ``i`` is ``(vertices, edges, closed)`` with ``vertices`` a
    (len+1,) int64 array of vertex indices along boundary ``i`` (first == last when closed),
    ``edges`` the (len,) int64 edge indices in walking order and ``closed`` a bool.
    Walks start at a corner (lowest corner vertex) or, for corner-free loops, at the lowest vertex,
    along the lowest edge of the boundary there, and go on along the lowest edge not walked yet
    until a corner, or until every edge of the boundary is walked.
    """
    w = boundary_walks(topology, layout, which)
    chains = []
    for b, (lo, n, c, walked) in enumerate(zip(w.offsets.tolist(), w.length.tolist(),
                                                 w.closed.tolist(), w.walked.tolist())):
        chains.append((w.vertices[lo + b:lo + b + n + 1], w.edges[lo:lo + n], c)
                      if walked else None)
    return chains


@numba.njit(cache=True, nogil=True)
def _walk_boundaries(sep_vertices, degree, sep_boundary, n_b, walk):
    """The walks of :func:`boundary_chains` over the separating edges (vertex pairs
    ``sep_vertices``, (k, 2)) of the boundaries flagged in ``walk``.

    Returns
    -------
    chain_v : int64 vertices of the walks, ``offsets[b] + b`` to ``offsets[b] + b + length[b]``
        (inclusive) the walk of boundary ``b``.
    chain_e : int64 positions in ``sep_vertices`` of the walked edges, ``offsets[b]`` to
        ``offsets[b] + length[b]`` (exclusive) those of boundary ``b``.
    offsets : (b,) int64 room of each boundary (its edges before it, among the flagged ones).
    length : (b,) int64 edges walked on each boundary.
    closed : (b,) bool, True for a boundary without a corner.
    """
    k = len(sep_vertices)
    n = len(degree)
    # separating edges at each vertex, ascending (filled in edge order)
    start = np.zeros(n + 1, dtype=np.int64)
    for i in range(k):
        start[sep_vertices[i, 0] + 1] += 1
        start[sep_vertices[i, 1] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    incident = np.empty(2 * k, dtype=np.int64)
    for i in range(k):
        for end in range(2):
            v = sep_vertices[i, end]
            incident[fill[v]] = i
            fill[v] += 1
    # start vertex: lowest corner vertex, else lowest vertex
    size = np.zeros(n_b, dtype=np.int64)
    low_corner = np.full(n_b, n, dtype=np.int64)
    low_any = np.full(n_b, n, dtype=np.int64)
    for i in range(k):
        b = sep_boundary[i]
        size[b] += 1
        for end in range(2):
            v = sep_vertices[i, end]
            low_any[b] = min(low_any[b], v)
            if degree[v] != 2:
                low_corner[b] = min(low_corner[b], v)
    offsets = np.zeros(n_b + 1, dtype=np.int64)
    for b in range(n_b):
        offsets[b + 1] = offsets[b] + (size[b] if walk[b] else 0)
    chain_e = np.empty(offsets[n_b], dtype=np.int64)
    chain_v = np.empty(offsets[n_b] + n_b, dtype=np.int64)
    closed = low_corner == n
    used = np.zeros(k, dtype=np.bool_)
    length = np.zeros(n_b, dtype=np.int64)
    for b in range(n_b):
        if not walk[b]:
            continue
        v = low_any[b] if closed[b] else low_corner[b]
        pos_v = offsets[b] + b
        chain_v[pos_v] = v
        pos_v += 1
        count = 0
        e = -1
        for j in range(start[v], start[v + 1]):
            if sep_boundary[incident[j]] == b:
                e = incident[j]
                break
        while e >= 0:
            used[e] = True
            chain_e[offsets[b] + count] = e
            count += 1
            v = sep_vertices[e, 1] if sep_vertices[e, 0] == v else sep_vertices[e, 0]
            chain_v[pos_v] = v
            pos_v += 1
            if degree[v] != 2 or count == size[b]:
                break
            e = -1
            for j in range(start[v], start[v + 1]):
                if not used[incident[j]] and sep_boundary[incident[j]] == b:
                    e = incident[j]
                    break
        length[b] = count
    return chain_v, chain_e, offsets[:-1], length, closed

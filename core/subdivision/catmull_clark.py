# SPDX-License-Identifier: LGPL-2.1-or-later
"""Catmull-Clark subdivision of closed polygon meshes as sparse matrices.

The rules are the ones OpenSubdiv's Catmull-Clark scheme applies to a closed mesh
(the default "Catmark" triangle rule, so triangles and n-gons get no special weights):

* face point: average of the face's corners;
* edge point: ``(v0 + v1 + f0 + f1) / 4`` with ``f0, f1`` the adjacent face points;
* vertex point of a valence-``n`` vertex: ``(Q + 2 R + (n - 3) S) / n``, i.e.
  ``(n - 2) / n * S + 1 / n**2 * (sum of neighbours + sum of adjacent face points)``.

Edges may be tagged as infinitely sharp creases (``PolyMesh.creases``; Hoppe et al. 1994,
DeRose, Kass & Truong 1998, OpenSubdiv's rules for sharpness infinity):

* edge point of a crease edge: its midpoint;
* vertex with exactly two crease edges (crease vertex): ``(e0 + 6 v + e1) / 8``, ``e0, e1``
  its neighbours along the creases (the cubic B-spline curve rule);
* vertex with three or more crease edges (corner): stays put;
* vertex with one crease edge (dart): the smooth rule.

Both halves of a crease edge are crease edges of the refined mesh, so a crease's limit is
the uniform cubic B-spline curve of its crease polygon. Without creases the matrices are
bit-identical to those of the smooth rules alone.

Child vertex numbering: vertex points first (so a base vertex keeps its index at
every level), then one face point per face, then one edge point per edge.
Child faces are face-major: child ``j`` of face ``f`` is face ``face_offsets[f] + j``
of the refined mesh, the quad ``(v_j, e(j, j+1), f, e(j-1, j))`` that keeps the
parent's orientation.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from core.errors import InvalidMeshError, ParameterError
from core.mesh_topology import next_corners, previous_corners
from core.types import PolyMesh


@dataclass(frozen=True)
class Topology:
    """Half-edge tables of a polygon mesh (all int64).

    face_of_corner : (k,) face of each corner (corner = entry of ``face_vertices``).
    next_corner, prev_corner : (k,) next / previous corner in the same face.
    edges : (e, 2) sorted vertex pairs of the undirected edges.
    corner_edge : (k,) edge of the half-edge from corner ``c`` to ``next_corner[c]``.
    edge_face_count : (e,) number of half-edges on each edge (2 on a closed manifold).
    twin : (k,) corner starting the opposite half-edge, ``-1`` on boundary edges.
    """

    face_of_corner: np.ndarray
    next_corner: np.ndarray
    prev_corner: np.ndarray
    edges: np.ndarray
    corner_edge: np.ndarray
    edge_face_count: np.ndarray
    twin: np.ndarray

    def edge_index(self, a, b):
        """(p,) int64 index of the undirected edges ``(a, b)``; ``-1`` where absent."""
        a = np.asarray(a, dtype=np.int64)
        b = np.asarray(b, dtype=np.int64)
        n = int(self.edges.max()) + 1 if len(self.edges) else 1
        keys = self.edges[:, 0] * n + self.edges[:, 1]
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        valid = hi < n
        query = np.where(valid, lo * n + hi, -1)
        pos = np.clip(np.searchsorted(keys, query), 0, max(len(keys) - 1, 0))
        found = valid & (keys[pos] == query)
        return np.where(found, pos, -1)


def mesh_topology(face_vertices, face_offsets, n_vertices):
    """Build the :class:`Topology` of a polygon mesh (vectorised).

    Parameters
    ----------
    face_vertices : (k,) int64 corners of all faces.
    face_offsets : (m + 1,) int64 CSR offsets.
    n_vertices : int

    Returns
    -------
    Topology
    """
    fv = np.asarray(face_vertices, dtype=np.int64)
    fo = np.asarray(face_offsets, dtype=np.int64)
    k = len(fv)
    sizes = np.diff(fo)
    face_of_corner = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    next_corner = next_corners(fo)
    prev_corner = previous_corners(fo)
    a = fv
    b = fv[next_corner]
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    keys = lo * np.int64(max(n_vertices, 1)) + hi
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    is_first = np.ones(k, dtype=bool)
    is_first[1:] = sorted_keys[1:] != sorted_keys[:-1]
    edge_of_sorted = np.cumsum(is_first) - 1
    corner_edge = np.empty(k, dtype=np.int64)
    corner_edge[order] = edge_of_sorted
    first_pos = np.flatnonzero(is_first)
    edges = np.stack([lo[order[first_pos]], hi[order[first_pos]]], axis=1)
    edge_face_count = np.bincount(corner_edge, minlength=len(edges)).astype(np.int64)
    twin = np.full(k, -1, dtype=np.int64)
    pair = np.flatnonzero(~is_first[1:] & is_first[:-1]) if k > 1 else np.zeros(0, np.int64)
    pair = pair[edge_face_count[edge_of_sorted[pair]] == 2]
    twin[order[pair]] = order[pair + 1]
    twin[order[pair + 1]] = order[pair]
    return Topology(face_of_corner, next_corner, prev_corner, edges, corner_edge,
                    edge_face_count, twin)


def _face_point_matrix(fv, fo, face_of_corner, n):
    sizes = np.diff(fo).astype(np.float64)
    return sp.csr_matrix((1.0 / sizes[face_of_corner], (face_of_corner, fv)),
                         shape=(len(sizes), n))


def crease_edge_mask(topology, creases):
    """(e,) bool: which edges of ``topology`` are crease edges.

    Parameters
    ----------
    topology : Topology of the mesh.
    creases : None or (c, 2) int vertex pairs (``PolyMesh.creases``).

    Raises
    ------
    InvalidMeshError (``crease_not_edge``) when a pair is not an edge of the mesh.
    """
    mask = np.zeros(len(topology.edges), dtype=bool)
    if creases is None or len(creases) == 0:
        return mask
    pairs = np.asarray(creases, dtype=np.int64).reshape(-1, 2)
    index = topology.edge_index(pairs[:, 0], pairs[:, 1])
    missing = np.flatnonzero(index < 0)
    if len(missing):
        raise InvalidMeshError(
            f"{len(missing)} crease pairs are not edges of the mesh, e.g. "
            f"{pairs[missing[:5]].tolist()}", reason="crease_not_edge", count=len(missing),
            examples=pairs[missing[:5]].tolist())
    mask[index] = True
    return mask


def vertex_crease_counts(topology, crease, n_vertices):
    """(n,) int64 number of crease edges at every vertex (``crease``: (e,) bool edge mask)."""
    return np.bincount(topology.edges[crease].reshape(-1), minlength=n_vertices).astype(np.int64)


def child_creases(topology, crease, n_vertices, n_faces):
    """Crease pairs of the refined mesh of :func:`subdivision_operator`.

    Parameters
    ----------
    topology : Topology of the parent mesh; crease : (e,) bool crease edges of it.
    n_vertices, n_faces : int, vertices and faces of the parent mesh.

    Returns
    -------
    None when there are no crease edges, else (2 c, 2) int64: both halves
    ``(v, edge point)`` of every crease edge, in the child's vertex numbering.
    """
    index = np.flatnonzero(crease)
    if not len(index):
        return None
    mid = n_vertices + n_faces + index
    ends = topology.edges[index]
    return np.concatenate([np.stack([ends[:, 0], mid], axis=1),
                           np.stack([ends[:, 1], mid], axis=1)])


def subdivision_operator(face_vertices, face_offsets, n_vertices, allow_open=False,
                         creases=None):
    """One Catmull-Clark step on raw arrays.

    Parameters
    ----------
    face_vertices : (k,) int64
    face_offsets : (m + 1,) int64
    n_vertices : int
    allow_open : bool
        If False (default) every edge must have exactly two faces. If True,
        boundary edges get their midpoint and boundary vertices stay put; those
        rows are not Catmull-Clark (used only for local templates that are
        cropped away from their boundary).
    creases : None or (c, 2) int vertex pairs of crease edges (module docstring);
        :func:`child_creases` gives the refined mesh's.

    Returns
    -------
    child_face_vertices : (4 k,) int64, all quads.
    child_face_offsets : (k + 1,) int64
    S : (n + m + e, n) scipy.sparse.csr_matrix float64, rows sum to 1.
    topology : Topology of the parent mesh.
    """
    fv = np.asarray(face_vertices, dtype=np.int64)
    fo = np.asarray(face_offsets, dtype=np.int64)
    n = int(n_vertices)
    m = len(fo) - 1
    topo = mesh_topology(fv, fo, n)
    count = topo.edge_face_count
    if not allow_open and len(count) and (count != 2).any():
        bad = np.flatnonzero(count != 2)
        raise InvalidMeshError(
            f"Catmull-Clark needs a closed 2-manifold mesh; {len(bad)} edges do not have "
            f"exactly two faces, e.g. {topo.edges[bad[0]].tolist()}",
            reason="open" if (count[bad] == 1).all() else "non_manifold",
            count=len(bad), examples=topo.edges[bad[:5]].tolist())
    n_edges = len(topo.edges)
    face_pts = _face_point_matrix(fv, fo, topo.face_of_corner, n)
    crease = crease_edge_mask(topo, creases)

    interior_edge = (count == 2) & ~crease
    end_w = np.where(interior_edge, 0.25, 0.5)
    edge_ends = sp.csr_matrix(
        (np.repeat(end_w, 2), (np.repeat(np.arange(n_edges), 2), topo.edges.reshape(-1))),
        shape=(n_edges, n))
    face_w = np.where(interior_edge, 0.25, 0.0)[topo.corner_edge]
    edge_faces = sp.csr_matrix((face_w, (topo.corner_edge, topo.face_of_corner)),
                               shape=(n_edges, m))
    edge_pts = (edge_ends + edge_faces @ face_pts).tocsr()

    valence = np.bincount(fv, minlength=n).astype(np.float64)
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[topo.edges[count != 2].reshape(-1)] = True
    n_crease = vertex_crease_counts(topo, crease, n)
    corner = on_boundary | (n_crease >= 3)
    crease_vertex = ~corner & (n_crease == 2)
    safe_val = np.maximum(valence, 1.0)
    inv_n2 = 1.0 / safe_val ** 2
    inv_n2[corner | crease_vertex] = 0.0
    self_w = np.where(corner | (valence == 0), 1.0,
                      np.where(crease_vertex, 0.75, (safe_val - 2.0) / safe_val))
    nb_rows = topo.edges.reshape(-1)
    nb_cols = topo.edges[:, ::-1].reshape(-1)
    nb_w = np.where(crease_vertex[nb_rows], np.where(np.repeat(crease, 2), 0.125, 0.0),
                    inv_n2[nb_rows])
    neighbours = sp.csr_matrix((nb_w, (nb_rows, nb_cols)), shape=(n, n))
    vert_faces = sp.csr_matrix((inv_n2[fv], (fv, topo.face_of_corner)), shape=(n, m))
    vert_pts = (sp.diags(self_w) + neighbours + vert_faces @ face_pts).tocsr()

    S = sp.vstack([vert_pts, face_pts, edge_pts], format="csr")
    S.sum_duplicates()
    if crease.any():
        S.eliminate_zeros()

    c = np.arange(len(fv), dtype=np.int64)
    child = np.stack([
        fv,
        n + m + topo.corner_edge[c],
        n + topo.face_of_corner,
        n + m + topo.corner_edge[topo.prev_corner],
    ], axis=1).reshape(-1)
    child_offsets = np.arange(0, 4 * len(fv) + 1, 4, dtype=np.int64)
    return child, child_offsets, S, topo


def subdivide(mesh):
    """One Catmull-Clark step of a closed polygon mesh.

    Parameters
    ----------
    mesh : PolyMesh, closed 2-manifold, faces of any size >= 3.

    Returns
    -------
    refined : PolyMesh, all quads (one per corner of ``mesh``), vertices ``S @ V``, the
        halves of ``mesh``'s crease edges as its creases.
    S : (n_fine, n_coarse) scipy.sparse.csr_matrix float64, every row sums to 1.

    Raises
    ------
    InvalidMeshError
        ``open`` / ``non_manifold`` if an edge does not have exactly two faces,
        ``crease_not_edge`` if a crease pair is not an edge.
    """
    n = len(mesh.vertices)
    fv, fo, S, topo = subdivision_operator(mesh.face_vertices, mesh.face_offsets, n,
                                           creases=mesh.creases)
    creases = child_creases(topo, crease_edge_mask(topo, mesh.creases), n, mesh.n_faces)
    return PolyMesh(S @ np.asarray(mesh.vertices, dtype=np.float64), fv, fo, creases), S


@dataclass
class SubdivisionHierarchy:
    """Meshes and matrices of ``levels`` Catmull-Clark steps (paper Eqs. 4-5).

    meshes : list of PolyMesh, ``meshes[0]`` is the base mesh, ``meshes[i]`` level i.
    matrices : list of csr_matrix, ``matrices[i]`` is S^(i) mapping level i to i + 1.
    """

    meshes: list
    matrices: list
    _composites: dict = field(default_factory=dict, repr=False)

    @property
    def levels(self):
        return len(self.matrices)

    def composite(self, i):
        """S_i = S^(i) ... S^(0), the (n_{i+1}, n_0) csr matrix mapping base to level i + 1.

        ``composite(-1)`` is the identity. Results are cached.
        """
        if i < -1 or i >= self.levels:
            raise ParameterError(f"composite index {i} outside -1..{self.levels - 1}")
        if i == -1:
            return sp.identity(len(self.meshes[0].vertices), format="csr")
        if i not in self._composites:
            prev = self.composite(i - 1) if i > 0 else None
            self._composites[i] = (self.matrices[0] if prev is None
                                   else (self.matrices[i] @ prev).tocsr())
        return self._composites[i]

    def positions(self, base_vertices, level):
        """(n_level, 3) float64 level-``level`` vertices for new base vertex positions."""
        X = np.asarray(base_vertices, dtype=np.float64)
        for i in range(level):
            X = self.matrices[i] @ X
        return X


def build_hierarchy(mesh, levels):
    """Subdivide ``mesh`` ``levels`` times, keeping every S^(i) and refined mesh.

    Parameters
    ----------
    mesh : PolyMesh, closed 2-manifold; its ``creases`` are subdivided with the crease rules
        and carried to every level.
    levels : int >= 0

    Returns
    -------
    SubdivisionHierarchy

    Raises
    ------
    ParameterError when ``levels < 0``; InvalidMeshError as :func:`subdivide`.
    """
    if levels < 0:
        raise ParameterError(f"subdivision levels must be >= 0, got {levels}")
    meshes = [mesh]
    mats = []
    for _ in range(levels):
        fine, S = subdivide(meshes[-1])
        meshes.append(fine)
        mats.append(S)
    return SubdivisionHierarchy(meshes, mats)


def fine_face_owner(base, level):
    """(n_fine,) int64 base face of every level-``level`` face (``level >= 1``).

    A base n-gon has n level-1 quads (one per corner, in corner order) and each quad four
    children, so the faces of one base face are contiguous, ``n * 4 ** (level - 1)`` of them.
    """
    return np.repeat(np.arange(base.n_faces), base.face_sizes * 4 ** (level - 1))


def face_grids(hierarchy, level):
    """Level-``level`` vertex ids on a regular grid over each base face of a quad mesh.

    Parameters
    ----------
    hierarchy : SubdivisionHierarchy whose base mesh is all quads, with at least
        ``level`` levels.
    level : int >= 0

    Returns
    -------
    (m, 2**level + 1, 2**level + 1) int64 array ``G``; ``G[f, i, j]`` is the vertex of
    mesh ``level`` at parameter ``(u, v) = (i, j) / 2**level`` of base face ``f``, where
    corner 0 of ``f`` is ``(0, 0)``, corner 1 ``(1, 0)``, corner 2 ``(1, 1)`` and
    corner 3 ``(0, 1)``.

    Raises
    ------
    InvalidMeshError (``not_quads``) when a base face is not a quad.
    """
    other = np.flatnonzero(hierarchy.meshes[0].face_sizes != 4)
    if len(other):
        raise InvalidMeshError(
            f"face grids need an all-quad base mesh: {len(other)} faces are not quads, e.g. "
            f"faces {other[:5].tolist()}", reason="not_quads", count=len(other),
            examples=other[:5].tolist())
    corners = hierarchy.meshes[level].face_vertices.reshape(-1, 4)
    grid = np.stack([np.stack([corners[:, 0], corners[:, 3]], axis=1),
                     np.stack([corners[:, 1], corners[:, 2]], axis=1)], axis=1)
    for lev in range(level - 1, -1, -1):
        h = grid.shape[1] - 1
        child = grid.reshape(-1, 4, h + 1, h + 1)
        parent = np.empty((len(child), 2 * h + 1, 2 * h + 1), dtype=np.int64)
        parent[:, :h + 1, :h + 1] = child[:, 0]
        parent[:, h:, :h + 1] = np.swapaxes(child[:, 1], 1, 2)[:, ::-1, :]
        parent[:, h:, h:] = child[:, 2, ::-1, ::-1]
        parent[:, :h + 1, h:] = np.swapaxes(child[:, 3], 1, 2)[:, :, ::-1]
        grid = parent
    return grid

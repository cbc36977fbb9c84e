# SPDX-License-Identifier: LGPL-2.1-or-later
"""Edge and adjacency tables of triangle meshes (vectorised, no per-face loops).

All functions take ``faces`` as an (m, 3) int64 array and return plain numpy /
scipy.sparse data, so every stage can share them.
"""
import numpy as np
import scipy.sparse as sp


def directed_edges(faces):
    """(3m, 2) int64 directed half-edges (a, b) of each face, face-major order.

    Row ``3 * f + k`` is the edge from corner ``k`` to corner ``k + 1`` of face ``f``.
    """
    faces = np.asarray(faces, dtype=np.int64)
    return np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)


def unique_edges(faces):
    """Undirected edges and the map from half-edges to them.

    Returns
    -------
    edges : (e, 2) int64, sorted vertex pairs (a < b), lexicographic order.
    halfedge_edge : (3m,) int64, index into ``edges`` of each half-edge of
        :func:`directed_edges`.
    """
    half = np.sort(directed_edges(faces), axis=1)
    n = int(half.max()) + 1 if len(half) else 1
    code, halfedge_edge = np.unique(half[:, 0] * n + half[:, 1], return_inverse=True)
    edges = np.stack([code // n, code % n], axis=1)
    return edges, halfedge_edge.reshape(-1)


def edge_faces(faces):
    """Faces on each side of every undirected edge of a 2-manifold mesh.

    Returns
    -------
    edges : (e, 2) int64 sorted vertex pairs.
    faces_of_edge : (e, 2) int64, the two faces sharing each edge; ``-1`` where an
        edge has only one face (open mesh). Edges with more than two faces keep
        the first two (check manifoldness before relying on this).
    """
    edges, he_edge = unique_edges(faces)
    return edges, halfedge_faces(he_edge, len(edges))


def halfedge_faces(halfedge_edge, n_edges):
    """The two faces of every edge from the half-edge -> edge map of :func:`unique_edges`.

    Returns
    -------
    (n_edges, 2) int64, faces in half-edge order, ``-1`` where an edge has one face.
    """
    face_of_half = np.arange(len(halfedge_edge)) // 3
    order = np.argsort(halfedge_edge, kind="stable")
    first = np.searchsorted(halfedge_edge[order], np.arange(n_edges), side="left")
    count = np.bincount(halfedge_edge, minlength=n_edges)
    result = np.full((n_edges, 2), -1, dtype=np.int64)
    result[:, 0] = face_of_half[order[first]]
    has_two = count >= 2
    result[has_two, 1] = face_of_half[order[first[has_two] + 1]]
    return result


def faces_across(faces_of_edge, halfedge_edge):
    """(m, 3) int64 face across each edge (corner k to k+1) of every face, -1 on open edges.

    Parameters
    ----------
    faces_of_edge : (e, 2) int64 from :func:`halfedge_faces`; halfedge_edge : (3m,) int64.
    """
    own = np.arange(len(halfedge_edge)) // 3
    fe = faces_of_edge[halfedge_edge]
    return np.where(fe[:, 0] == own, fe[:, 1], fe[:, 0]).reshape(-1, 3)


def face_neighbours(faces):
    """(m, 3) int64 face across each edge (corner k to k+1) of every face, -1 on open edges."""
    edges, he_edge = unique_edges(faces)
    return faces_across(halfedge_faces(he_edge, len(edges)), he_edge)


def face_adjacency(faces):
    """(p, 2) int64 pairs of faces sharing an edge (each interior edge once)."""
    _, faces_of_edge = edge_faces(faces)
    return faces_of_edge[(faces_of_edge >= 0).all(axis=1)]


def face_adjacency_matrix(faces):
    """(m, m) CSR bool matrix, True where two faces share an edge."""
    pairs = face_adjacency(faces)
    m = len(faces)
    data = np.ones(2 * len(pairs), dtype=bool)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    return sp.csr_matrix((data, (rows, cols)), shape=(m, m))


def vertex_face_matrix(faces, n_vertices):
    """(n, m) CSR int8 incidence matrix, 1 where vertex ``i`` is a corner of face ``j``."""
    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    rows = faces.reshape(-1)
    cols = np.repeat(np.arange(m), 3)
    return sp.csr_matrix((np.ones(3 * m, dtype=np.int8), (rows, cols)), shape=(n_vertices, m))


def connected_face_components(faces):
    """(m,) int64 component id of each face (faces connected through shared edges)."""
    from scipy.sparse.csgraph import connected_components

    _, labels = connected_components(face_adjacency_matrix(faces), directed=False)
    return labels.astype(np.int64)


def next_corners(face_offsets):
    """(k,) int64 next corner in the same face of every corner of a polygon mesh.

    Parameters
    ----------
    face_offsets : (m + 1,) int64 CSR offsets of the faces into the corner array.
    """
    fo = np.asarray(face_offsets, dtype=np.int64)
    following = np.arange(int(fo[-1]), dtype=np.int64) + 1
    following[fo[1:] - 1] = fo[:-1]
    return following


def previous_corners(face_offsets):
    """(k,) int64 previous corner in the same face of every corner (inverse of
    :func:`next_corners`)."""
    fo = np.asarray(face_offsets, dtype=np.int64)
    preceding = np.arange(int(fo[-1]), dtype=np.int64) - 1
    preceding[fo[:-1]] = fo[1:] - 1
    return preceding


def neighbour_mean(vertices, face_vertices, face_offsets):
    """(n, 3) float64 mean of each vertex's edge neighbours in a polygon mesh.

    Each corner adds the next corner of its face, so in a closed, consistently oriented
    2-manifold every neighbour of a vertex counts once (one outgoing half-edge each).

    Parameters
    ----------
    vertices : (n, 3) float64; face_vertices : (k,) int64 corners; face_offsets : (m + 1,)
        int64 CSR offsets of the faces into them.
    """
    corners = np.asarray(face_vertices, dtype=np.int64)
    following = corners[next_corners(face_offsets)]
    total = np.zeros((len(vertices), 3))
    count = np.zeros(len(vertices))
    np.add.at(total, corners, np.asarray(vertices)[following])
    np.add.at(count, corners, 1.0)
    return total / np.maximum(count, 1.0)[:, None]


def euler_characteristic(n_vertices, faces):
    """``V - E + F`` of a triangle mesh with ``n_vertices`` vertices (int)."""
    edges, _ = unique_edges(faces)
    return n_vertices - len(edges) + len(faces)


def genus_of(n_vertices, faces, n_components):
    """Total genus of a closed manifold mesh from the Euler characteristic."""
    chi = euler_characteristic(n_vertices, faces)
    return int(round((2 * n_components - chi) / 2))


def polymesh_genus(mesh):
    """Total genus of a closed polygon mesh (``core.types.PolyMesh``, any face sizes) from the
    Euler characteristic, its components counted through shared vertices."""
    from scipy.sparse.csgraph import connected_components

    fv, fo = mesh.face_vertices, mesh.face_offsets
    face = np.repeat(np.arange(mesh.n_faces), np.diff(fo))
    a, b = fv, fv[next_corners(fo)]
    n = np.int64(len(mesh.vertices))
    edges = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    graph = sp.csr_matrix((np.ones(len(fv)), (fv, face)), shape=(len(mesh.vertices), mesh.n_faces))
    components, _ = connected_components(graph @ graph.T, directed=False)
    euler = len(mesh.vertices) - len(edges) + mesh.n_faces
    return int((2 * components - euler) // 2)


def polymesh_summary(mesh):
    """Counts of a closed polygon mesh (``core.types.PolyMesh``): the report's ``base_mesh``
    section and the cage object's figures.

    Returns
    -------
    dict of int: ``faces``, ``quads``, ``triangles``, ``other`` (faces of more than four
    corners), ``vertices``, ``extraordinary_vertices`` (valence other than 4) and ``genus``
    (from the Euler characteristic, one component).
    """
    fv, fo = mesh.face_vertices, mesh.face_offsets
    sizes = np.diff(fo)
    n = np.int64(len(mesh.vertices))
    a, b = fv, fv[next_corners(fo)]
    edges = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    valence = np.bincount(np.concatenate([edges // n, edges % n]), minlength=n)
    chi = int(n) - len(edges) + mesh.n_faces
    return {
        "faces": int(mesh.n_faces),
        "quads": int((sizes == 4).sum()),
        "triangles": int((sizes == 3).sum()),
        "other": int((sizes > 4).sum()),
        "vertices": int(n),
        "extraordinary_vertices": int((valence != 4).sum()),
        "genus": int(round((2 - chi) / 2)),
    }

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Topological operations on closed pure-quad meshes given as (q, 4) int64 arrays.

* :func:`free_loop_merge`: edge lines (straight through valence-4 vertices) that close into
  loops without meeting an irregular vertex or a group boundary can be removed; the faces on
  both sides then merge. Returns which faces merge.
* :func:`chord_refine`: split every quad chord (strip of quads joined through opposite edges)
  into the same number of pieces, so the refined mesh stays conforming.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.errors import InvalidMeshError


def components(n, a, b):
    """(n,) int64 connected component of each node of the graph with edges ``a``-``b``."""
    g = sp.csr_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)[1].astype(np.int64)


def unmatched_half_edges(quads):
    """Half-edges of a quad mesh that do not have exactly one opposite half-edge.

    Parameters
    ----------
    quads : (q, 4) int64 vertex ids.

    Returns
    -------
    bad : (4q,) bool, half-edge ``4 f + k`` (``quads[f, k] -> quads[f, k+1]``) occurs more
        than once or has no unique opposite.
    twin : (4q,) int64 an opposite half-edge (meaningful where ``bad`` is False).
    """
    a = quads.reshape(-1)
    b = np.roll(quads, -1, axis=1).reshape(-1)
    n = np.int64(quads.max()) + 1
    key = a * n + b
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    lo = np.searchsorted(sorted_key, b * n + a, side="left")
    hi = np.searchsorted(sorted_key, b * n + a, side="right")
    twin = order[np.minimum(lo, len(key) - 1)]
    count = np.searchsorted(sorted_key, key, side="right") - np.searchsorted(sorted_key, key)
    return (hi - lo != 1) | (count > 1), twin.astype(np.int64)


def half_edges(quads):
    """Half-edge structure of a closed quad mesh.

    Parameters
    ----------
    quads : (q, 4) int64 vertex ids, consistently oriented.

    Returns
    -------
    edge : (4q,) int64 undirected edge of half-edge ``4 f + k`` (``quads[f, k] -> quads[f, k+1]``).
    twin : (4q,) int64 opposite half-edge.
    n_edges : int.

    Raises
    ------
    InvalidMeshError if an edge does not have exactly one half-edge in each direction.
    """
    a = quads.reshape(-1)
    b = np.roll(quads, -1, axis=1).reshape(-1)
    n = np.int64(quads.max()) + 1
    bad, twin = unmatched_half_edges(quads)
    if bad.any():
        raise InvalidMeshError(f"quad mesh is not a closed oriented 2-manifold: {int(bad.sum())} "
                               f"half-edges without a unique opposite, e.g. "
                               f"{np.stack([a[bad], b[bad]], 1)[:5].tolist()}",
                               reason="non_manifold", count=int(bad.sum()),
                               examples=np.flatnonzero(bad)[:5].tolist())
    _, edge = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_inverse=True)
    return edge.astype(np.int64), twin, int(edge.max()) + 1


def free_loop_merge(quads, face_group):
    """Faces merged by removing every free edge loop.

    An edge line continues through a vertex of valence 4 along the opposite edge. A line is
    a free loop when it closes, all its vertices have valence 4 and each of its edges has
    faces of the same group on both sides. Removing all free loops merges faces; when groups
    are planar rectilinear charts cut by straight grid lines the merged regions are rectangles.

    Parameters
    ----------
    quads : (q, 4) int64 closed quad mesh.
    face_group : (q,) int64 group of each face (e.g. chart and orientation).

    Returns
    -------
    merged : (q,) int64 merged face id (0..k-1, numbered by lowest face).
    n_loops : int number of loops removed.
    """
    nq = len(quads)
    edge, twin, n_edges = half_edges(quads)
    h = np.arange(4 * nq)
    start = quads.reshape(-1)
    valence = np.bincount(start, minlength=int(quads.max()) + 1)
    prev = (h // 4) * 4 + (h - 1) % 4
    rot = twin[prev]
    opposite = rot[rot]
    straight = valence[start] == 4
    line = components(n_edges, edge[h[straight]], edge[opposite[straight]])
    face = h // 4
    interior = face_group[face] == face_group[face[twin]]
    ok_half = straight & interior & (valence[quads[face, (h + 1) % 4].reshape(-1)] == 4)
    bad_line = np.bincount(line[edge[~ok_half]], minlength=n_edges) > 0
    removed = ~bad_line[line]
    n_loops = len(np.unique(line[removed]))
    rh = h[removed[edge]]
    merged = components(nq, face[rh], face[twin[rh]])
    first = np.full(nq, nq, dtype=np.int64)
    np.minimum.at(first, merged, np.arange(nq))
    rank = np.empty(nq, dtype=np.int64)
    used = np.unique(merged)
    rank[used[np.argsort(first[used], kind="stable")]] = np.arange(len(used))
    return rank[merged], n_loops


def chord_pieces(quads, positions, h):
    """Pieces each edge is split into: ``ceil(longest edge of its chord / h)``.

    Parameters
    ----------
    quads : (q, 4) int64 closed quad mesh; positions : (n, 3) float64; h : float > 0.

    Returns
    -------
    pieces : (e,) int64 per undirected edge (numbering of :func:`half_edges`).
    edge : (4q,) int64 edge of each half-edge.
    """
    nq = len(quads)
    edge, _, n_edges = half_edges(quads)
    hh = np.arange(4 * nq)
    opp = (hh // 4) * 4 + (hh + 2) % 4
    chord = components(n_edges, edge, edge[opp])
    a = quads.reshape(-1)
    b = np.roll(quads, -1, axis=1).reshape(-1)
    length = np.linalg.norm(positions[b] - positions[a], axis=1)
    longest = np.zeros(chord.max() + 1)
    np.maximum.at(longest, chord[edge], length)
    pieces = np.maximum(1, np.ceil(longest / h - 1e-9)).astype(np.int64)[chord]
    return pieces, edge


def chord_refine(quads, positions, pieces, edge):
    """Split every quad into ``pieces`` of its edges (bilinear positions).

    Parameters
    ----------
    quads : (q, 4) int64; positions : (n, 3) float64.
    pieces, edge : from :func:`chord_pieces` (opposite edges of a quad have equal pieces).

    Returns
    -------
    quads : (q', 4) int64 refined quads (same orientation).
    positions : (n', 3) float64, the first n are the input vertices.
    vertex_face : (n',) int64 a coarse face each vertex lies on.
    quad_face : (q',) int64 coarse face of each refined quad (ascending).
    """
    nq, n = len(quads), len(positions)
    he = edge.reshape(nq, 4)
    n0, n1 = pieces[he[:, 0]], pieces[he[:, 1]]
    n_edges = len(pieces)
    # vertices inside edges, then inside faces
    e_count = pieces - 1
    e_base = n + np.concatenate([[0], np.cumsum(e_count)[:-1]])
    lo = np.zeros(n_edges, dtype=np.int64)
    hi = np.zeros(n_edges, dtype=np.int64)
    a = quads.reshape(-1)
    b = np.roll(quads, -1, axis=1).reshape(-1)
    lo[edge], hi[edge] = np.minimum(a, b), np.maximum(a, b)
    edge_face = np.zeros(n_edges, dtype=np.int64)
    edge_face[edge[::-1]] = (np.arange(4 * nq) // 4)[::-1]
    f_count = (n0 - 1) * (n1 - 1)
    f_base = n + int(e_count.sum()) + np.concatenate([[0], np.cumsum(f_count)[:-1]])
    total = n + int(e_count.sum()) + int(f_count.sum())
    out_pos = np.zeros((total, 3))
    out_pos[:n] = positions
    vertex_face = np.zeros(total, dtype=np.int64)
    vertex_face[quads.reshape(-1)[::-1]] = (np.arange(4 * nq) // 4)[::-1]
    e_of = np.repeat(np.arange(n_edges), e_count)
    k = np.arange(len(e_of)) - np.repeat(e_base - n, e_count)
    t = (k + 1) / pieces[e_of]
    out_pos[n:n + len(e_of)] = (positions[lo[e_of]] * (1 - t)[:, None]
                                + positions[hi[e_of]] * t[:, None])
    vertex_face[n:n + len(e_of)] = edge_face[e_of]
    new_quads = []
    for p0, p1 in np.unique(np.stack([n0, n1], axis=1), axis=0):
        fs = np.flatnonzero((n0 == p0) & (n1 == p1))
        g = len(fs)
        ids = np.zeros((g, p0 + 1, p1 + 1), dtype=np.int64)
        q = quads[fs]
        ids[:, 0, 0], ids[:, p0, 0], ids[:, p0, p1], ids[:, 0, p1] = q[:, 0], q[:, 1], q[:, 2], q[:, 3]

        def edge_points(e, v_from, count):
            """(g, count - 1) ids along edges ``e`` walking from ``v_from``."""
            kk = np.arange(1, count)[None, :]
            fwd = lo[e] == v_from
            return e_base[e][:, None] + np.where(fwd[:, None], kk - 1, count - kk - 1)

        if p0 > 1:
            ids[:, 1:p0, 0] = edge_points(he[fs, 0], q[:, 0], p0)
            ids[:, 1:p0, p1] = edge_points(he[fs, 2], q[:, 3], p0)
        if p1 > 1:
            ids[:, p0, 1:p1] = edge_points(he[fs, 1], q[:, 1], p1)
            ids[:, 0, 1:p1] = edge_points(he[fs, 3], q[:, 0], p1)
        if p0 > 1 and p1 > 1:
            inner = f_base[fs][:, None, None] + np.arange((p0 - 1) * (p1 - 1)).reshape(p0 - 1, p1 - 1)
            ids[:, 1:p0, 1:p1] = inner
            s = (np.arange(1, p0) / p0)[None, :, None, None]
            r = (np.arange(1, p1) / p1)[None, None, :, None]
            P = positions[q][:, :, None, None, :]
            pos = ((1 - s) * (1 - r) * P[:, 0] + s * (1 - r) * P[:, 1] + s * r * P[:, 2]
                   + (1 - s) * r * P[:, 3])
            out_pos[inner.reshape(-1)] = pos.reshape(-1, 3)
            vertex_face[inner.reshape(-1)] = np.repeat(fs, (p0 - 1) * (p1 - 1))
        sub = np.stack([ids[:, :-1, :-1], ids[:, 1:, :-1], ids[:, 1:, 1:], ids[:, :-1, 1:]], axis=-1)
        new_quads.append((fs, sub.reshape(g, -1, 4)))
    # keep the refined quads in coarse-face order (deterministic, independent of grouping)
    order = np.concatenate([np.repeat(fs, sub.shape[1]) for fs, sub in new_quads])
    flat = np.concatenate([sub.reshape(-1, 4) for _, sub in new_quads])
    by_face = np.argsort(order, kind="stable")
    return flat[by_face], out_pos, vertex_face, order[by_face]

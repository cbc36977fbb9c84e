# SPDX-License-Identifier: LGPL-2.1-or-later
"""Part segmentations of a closed triangle mesh (paper Sect. 2.1): the data, its checks and
the interfaces between parts.

A segmentation is a per-face array ``face_part`` (m,) int32 with parts 0 .. P-1, each
part non-empty and edge-connected. Ways to get one:

- :func:`single_part`: the whole mesh is one part;
- :func:`parts_from_user`: a per-face array, face-index groups or cutting planes;
- :func:`core.segmentation.skeleton_parts.automatic_parts`: curve-skeleton pieces merged
  while one frame fits them.

:func:`interfaces` extracts the edge loops between parts (from :func:`interface_pieces`, the
one grouping of the edges between two parts into connected pieces), :func:`interface_x_axis`
is an interface's axis and :func:`face_interface_axes` gives it to the faces next to it: the
frames, the labeling's Eq. 3 term 4, the validity rules and the repair all use these.
"""
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from core.errors import ParameterError
from core.mesh_topology import edge_faces, face_adjacency


def _arrays(mesh):
    return (np.asarray(mesh.vertices, dtype=np.float64),
            np.asarray(mesh.faces, dtype=np.int64))


def part_components(pairs, face_part):
    """(m,) int64 id of the edge-connected component of each face within its part,
    and the number of components; ``pairs`` from ``core.mesh_topology.face_adjacency``."""
    face_part = np.asarray(face_part)
    same = pairs[face_part[pairs[:, 0]] == face_part[pairs[:, 1]]]
    m = len(face_part)
    graph = csr_matrix((np.ones(len(same)), (same[:, 0], same[:, 1])), shape=(m, m))
    n, comp = connected_components(graph, directed=False)
    return comp.astype(np.int64), n


def canonical_order(face_part):
    """Renumber parts 0 .. P-1 by the smallest face index each contains; (m,) int32."""
    face_part = np.asarray(face_part, dtype=np.int64)
    uniq, first = np.unique(face_part, return_index=True)
    rank = np.empty(len(uniq), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(uniq))
    return rank[np.searchsorted(uniq, face_part)].astype(np.int32)


def validate_face_part(mesh, face_part):
    """Check a per-face part array and return it as (m,) int32.

    Raises
    ------
    ParameterError
        Wrong length, non-integer values, negative ids, an empty part id (ids must be
        0 .. P-1) or a part that is not edge-connected; the message names the part
        and the counts.
    """
    _, faces = _arrays(mesh)
    m = len(faces)
    arr = np.asarray(face_part)
    if arr.ndim != 1 or len(arr) != m:
        raise ParameterError(f"face_part must have one entry per face ({m}), got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        bad = (np.flatnonzero(~np.isfinite(arr) | (arr != np.round(arr)))
               if arr.dtype.kind == "f" else np.arange(m))
        if len(bad):
            raise ParameterError(f"face_part must hold integers; {len(bad)} entries are not "
                                 f"(e.g. face {bad[0]})")
    arr = arr.astype(np.int64)
    if m and arr.min() < 0:
        neg = np.flatnonzero(arr < 0)
        raise ParameterError(f"face_part has {len(neg)} negative part ids (e.g. face {neg[0]})")
    n_parts = int(arr.max()) + 1 if m else 0
    counts = np.bincount(arr, minlength=n_parts)
    empty = np.flatnonzero(counts == 0)
    if len(empty):
        raise ParameterError(f"part ids must be 0..{n_parts - 1} without gaps; {len(empty)} "
                             f"parts are empty (e.g. part {empty[0]})")
    comp, _ = part_components(face_adjacency(faces), arr)
    n_comp = np.bincount(arr[np.unique(comp, return_index=True)[1]], minlength=n_parts)
    split = np.flatnonzero(n_comp > 1)
    if len(split):
        p = split[0]
        raise ParameterError(f"{len(split)} parts are not edge-connected: part {p} has "
                             f"{n_comp[p]} separate pieces")
    return arr.astype(np.int32)


def single_part(mesh):
    """(m,) int32 zeros: the whole mesh is one part."""
    return np.zeros(len(np.asarray(mesh.faces)), dtype=np.int32)


def split_disconnected(faces, face_part):
    """Give every edge-connected piece of every part its own part; canonical (m,) int32."""
    comp, _ = part_components(face_adjacency(faces), np.asarray(face_part, dtype=np.int64))
    return canonical_order(comp)


def parts_from_face_groups(mesh, groups):
    """Parts from a list of face-index lists (group k -> part k); every face exactly once."""
    _, faces = _arrays(mesh)
    m = len(faces)
    if len(groups) == 0:
        raise ParameterError("face groups are empty: give at least one group")
    out = np.full(m, -1, dtype=np.int64)
    seen = np.zeros(m, dtype=np.int64)
    for k, grp in enumerate(groups):
        idx = np.asarray(grp)
        if idx.ndim != 1 or (len(idx) and idx.dtype.kind not in "iu"):
            raise ParameterError(f"face group {k} must be a flat list of integer face indices")
        idx = idx.astype(np.int64)
        if len(idx) == 0:
            raise ParameterError(f"face group {k} is empty")
        bad = idx[(idx < 0) | (idx >= m)]
        if len(bad):
            raise ParameterError(f"face group {k} has {len(bad)} indices outside 0..{m - 1} "
                                 f"(e.g. {bad[0]})")
        np.add.at(seen, idx, 1)
        out[idx] = k
    twice = np.flatnonzero(seen > 1)
    if len(twice):
        raise ParameterError(f"{len(twice)} faces are listed more than once (e.g. face {twice[0]})")
    missing = np.flatnonzero(seen == 0)
    if len(missing):
        raise ParameterError(f"{len(missing)} faces are in no group (e.g. face {missing[0]}); "
                             f"every face must belong to exactly one group")
    return validate_face_part(mesh, out)


def parts_from_planes(mesh, planes):
    """Parts from cutting planes ``[(point, normal), ...]``.

    A face goes to the cell given by the signs of ``(centroid - point) . normal`` over all
    planes; every cell is then split into edge-connected parts. Canonical numbering.
    """
    vertices, faces = _arrays(mesh)
    centroid = vertices[faces].mean(axis=1)
    code = np.zeros(len(faces), dtype=np.int64)
    for k, plane in enumerate(planes):
        try:
            point, normal = (np.asarray(x, dtype=np.float64) for x in plane)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"plane {k} must be (point, normal), got {plane!r}") from exc
        if point.shape != (3,) or normal.shape != (3,) or not np.isfinite([point, normal]).all():
            raise ParameterError(f"plane {k} needs a finite 3-D point and normal")
        if np.linalg.norm(normal) == 0:
            raise ParameterError(f"plane {k} has a zero normal")
        code = code * 2 + ((centroid - point) @ normal >= 0)
    return split_disconnected(faces, code)


def parts_from_user(mesh, spec):
    """Parts chosen by the user.

    Parameters
    ----------
    mesh : object with ``vertices`` (n, 3) and ``faces`` (m, 3).
    spec : one of
        - a per-face part array (m,) of integers 0 .. P-1 (each part edge-connected);
        - a list of face-index lists (group k is part k; each face in exactly one group);
        - a list of cutting planes ``(point, normal)`` (see :func:`parts_from_planes`).

    Returns
    -------
    (m,) int32 face_part.
    """
    if isinstance(spec, np.ndarray) and spec.ndim == 1:
        return validate_face_part(mesh, spec)
    seq = list(spec)
    if seq and all(np.ndim(x) == 0 for x in seq):
        return validate_face_part(mesh, np.asarray(seq))
    if seq and all(map(_is_pair, seq)):
        return parts_from_planes(mesh, seq)
    return parts_from_face_groups(mesh, seq)


def _is_pair(x):
    try:
        return len(x) == 2 and all(np.shape(y) == (3,) for y in x)
    except TypeError:
        return False


# ----------------------------------------------------------------------------------------
# interfaces

@dataclass
class Interface:
    """Boundary between two parts (one connected piece of it).

    parts : (i, j) with i < j.
    loops : list of (k,) int64 vertex chains along the boundary; a closed loop does not
        repeat its first vertex.
    closed : list of bool, one per loop.
    vertices : (v,) int64 sorted vertices on the boundary.
    edges : (e, 2) int64 boundary edges (sorted vertex pairs).
    frame : (3, 3) float64 rows x, y, z, set by :func:`core.segmentation.frames.compute_frames`.
    """

    parts: tuple
    loops: list
    closed: list
    vertices: np.ndarray
    edges: np.ndarray
    frame: np.ndarray = field(default=None)


def _chains(edges):
    """Walk undirected edges (k, 2) into chains; deterministic (smallest indices first)."""
    incident = {}
    for e, (a, b) in enumerate(edges.tolist()):
        incident.setdefault(a, []).append(e)
        incident.setdefault(b, []).append(e)
    used = np.zeros(len(edges), dtype=bool)
    starts = sorted(v for v, es in incident.items() if len(es) % 2 == 1)
    starts += sorted(incident)
    chains, closed = [], []
    for s in starts:
        while any(not used[e] for e in incident[s]):
            chain, v = [s], s
            while True:
                nxt = [e for e in incident[v] if not used[e]]
                if not nxt:
                    break
                e = min(nxt)
                used[e] = True
                a, b = edges[e]
                v = int(b if a == v else a)
                chain.append(v)
                if v == s:
                    break
            is_closed = len(chain) > 2 and chain[-1] == chain[0]
            chains.append(np.array(chain[:-1] if is_closed else chain, dtype=np.int64))
            closed.append(is_closed)
    return chains, closed


def interface_pieces(edges, edges_faces, face_part, n_vertices):
    """The edges between two parts, grouped into the connected pieces of each pair's boundary.

    Parameters
    ----------
    edges : (e, 2) int64 sorted vertex pairs; edges_faces : (e, 2) int64 the two faces of
        each edge, -1 where missing (``core.mesh_topology.edge_faces`` or
        ``core.segmentation.charts.MeshTopology``).
    face_part : (m,) int part of each face; n_vertices : int.

    Returns
    -------
    list of ``((i, j), index)``: the parts ``i < j`` and the (k,) int64 indices into ``edges``
    of one connected piece (edges joined at shared vertices), in edge order; ordered by
    ``(i, j)``, then by the piece's smallest vertex.
    """
    face_part = np.asarray(face_part, dtype=np.int64)
    ok = (edges_faces >= 0).all(axis=1)
    pa, pb = face_part[edges_faces[:, 0]], face_part[np.maximum(edges_faces[:, 1], 0)]
    cut = np.flatnonzero(ok & (pa != pb))
    pair = np.sort(np.stack([pa[cut], pb[cut]], axis=1), axis=1)
    out = []
    for i, j in np.unique(pair, axis=0).tolist():
        index = cut[(pair[:, 0] == i) & (pair[:, 1] == j)]
        e = edges[index]
        graph = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
        _, comp = connected_components(graph, directed=False)
        ce = comp[e[:, 0]]
        for c in sorted(np.unique(ce).tolist(), key=lambda c: e[ce == c].min()):
            out.append(((i, j), index[ce == c]))
    return out


def interfaces(mesh, face_part):
    """Interfaces between parts.

    One record per connected piece of the boundary between two parts
    (:func:`interface_pieces`: normally one closed loop per adjacent pair; open chains where
    three parts meet).

    Returns
    -------
    list of :class:`Interface`, ordered by (i, j) then smallest vertex.
    """
    vertices, faces = _arrays(mesh)
    edges, fe = edge_faces(faces)
    out = []
    for parts, index in interface_pieces(edges, fe, face_part, len(vertices)):
        ec = edges[index]
        loops, closed = _chains(ec)
        out.append(Interface(parts, loops, closed, np.unique(ec), ec))
    return out


def interface_x_axis(points):
    """Unit x-axis of an interface for Eq. 3 term 4 and the validity rules (Eq. 1 literally).

    The eigenvector of the smallest eigenvalue of the covariance of the interface's vertices
    ``points`` ((k, 3) float64, in vertex order); for a planar loop, the normal of its plane.
    The one definition of the axis: the frames, the labeling, the validity judgement and the
    repair all take it from here.
    """
    p = np.asarray(points, dtype=np.float64)
    p = p - p.mean(axis=0)
    return np.linalg.eigh(p.T @ p)[1][:, 0]


def face_interface_axes(faces, face_part, interfaces, vertices):
    """Faces next to an interface and that interface's x-axis (term 4 of Eq. 3).

    A face is next to an interface when one of its vertices lies on it (so the faces along an
    interface form a connected band and no chart of a label parallel to the axis reaches the
    interface, not even at a vertex) and it belongs to one of the interface's two parts; where
    a face touches several interfaces the lowest interface index is used. The axis is
    :func:`interface_x_axis` of the interface's vertices, the axis
    :func:`core.segmentation.validity.check_validity` judges interface edges with.

    Parameters
    ----------
    faces : (m, 3) int64; face_part : (m,) int.
    interfaces : list of :class:`Interface`.
    vertices : (n, 3) float64.

    Returns
    -------
    face_interface : (m,) int64 interface index, -1 where the face touches none.
    axis : (m, 3) float64 unit x-axis of that interface, NaN rows where none.
    """
    faces = np.asarray(faces, dtype=np.int64)
    face_part = np.asarray(face_part, dtype=np.int64)
    m = len(face_part)
    none = np.iinfo(np.int64).max
    face_interface = np.full(m, none)
    n_v = len(vertices)
    for k, itf in enumerate(interfaces):
        on = np.zeros(n_v, dtype=bool)
        on[itf.vertices] = True
        touch = on[faces].any(axis=1) & np.isin(face_part, itf.parts)
        face_interface[touch] = np.minimum(face_interface[touch], k)
    face_interface[face_interface == none] = -1
    axis = np.full((m, 3), np.nan)
    has = face_interface >= 0
    if has.any():
        pts = np.asarray(vertices, dtype=np.float64)
        xs = np.array([interface_x_axis(pts[itf.vertices]) for itf in interfaces])
        axis[has] = xs[face_interface[has]]
    return face_interface, axis

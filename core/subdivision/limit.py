# SPDX-License-Identifier: LGPL-2.1-or-later
"""Catmull-Clark limit masks and exact limit-surface evaluation on all-quad meshes.

* :func:`limit_matrices` gives the exact limit position and two limit tangents of
  every vertex of a closed all-quad mesh (valence-``n`` masks, Halstead et al. 1993).
* :class:`LimitEvaluator` evaluates the limit surface exactly at any parameter of a
  face: regular sub-quads are uniform bicubic B-splines; near an extraordinary
  vertex (EV) the neighbourhood is subdivided locally with an exact template
  matrix until the point falls into a regular sub-quad (the idea of Stam 1998,
  with repeated local subdivision instead of an eigen decomposition).
"""
import functools

import numpy as np
import scipy.sparse as sp

from core.errors import InternalError, InvalidMeshError, ParameterError
from core.geometry import polymesh_volume
from core.subdivision.catmull_clark import (build_hierarchy, crease_edge_mask, mesh_topology,
                                            subdivision_operator, vertex_crease_counts)

TEMPLATE_RADIUS = 3


def _require_closed_quads(mesh):
    """The ``Topology`` of ``mesh``, or InvalidMeshError when it is not a closed 2-manifold
    all-quad mesh (reason ``empty``, ``not_quads``, ``open`` or ``non_manifold``; the
    message counts the offending faces or edges and names a few)."""
    sizes = mesh.face_sizes
    if len(sizes) == 0:
        raise InvalidMeshError("limit masks need a non-empty all-quad mesh: it has no faces",
                               reason="empty")
    other = np.flatnonzero(sizes != 4)
    if len(other):
        raise InvalidMeshError(
            f"limit masks need an all-quad mesh: {len(other)} of {len(sizes)} faces are not "
            f"quads, e.g. faces {other[:5].tolist()} (subdivide once to turn any polygon mesh "
            "into quads)", reason="not_quads", count=len(other), examples=other[:5].tolist())
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    bad = np.flatnonzero(topo.edge_face_count != 2)
    if len(bad):
        open_ = (topo.edge_face_count[bad] == 1).all()
        raise InvalidMeshError(
            f"limit masks need a closed 2-manifold mesh: {len(bad)} edges have "
            f"{'one face' if open_ else 'one or more than two faces'}, e.g. edges (vertex "
            f"pairs) {topo.edges[bad[:5]].tolist()}", reason="open" if open_ else "non_manifold",
            count=len(bad), examples=topo.edges[bad[:5]].tolist())
    return topo


def spoke_order(mesh, topo):
    """Counter-clockwise position of every corner around its vertex.

    Parameters
    ----------
    mesh : PolyMesh, closed 2-manifold all-quad mesh.
    topo : Topology of ``mesh``.

    Returns
    -------
    spoke : (k,) int64, index ``i`` (0 .. valence - 1) of the half-edge leaving each
        corner among the half-edges leaving its vertex, counter-clockwise seen from
        outside.
    valence : (n,) int64 number of faces at each vertex.
    first : (n,) int64 the corner of each vertex with spoke index 0.
    """
    fv = mesh.face_vertices
    n = len(mesh.vertices)
    k = len(fv)
    valence = np.bincount(fv, minlength=n).astype(np.int64)
    first = np.full(n, -1, dtype=np.int64)
    first[fv[::-1]] = np.arange(k - 1, -1, -1, dtype=np.int64)
    rot = topo.twin[topo.prev_corner]
    spoke = np.full(k, -1, dtype=np.int64)
    has = first >= 0
    cur = first[has]
    val = valence[has]
    spoke[cur] = 0
    for t in range(1, int(valence.max())):
        cur = rot[cur]
        live = t < val
        spoke[cur[live]] = t
    return spoke, valence, first


def limit_matrices(quad_mesh):
    """Exact limit positions and limit tangents of every vertex of a closed quad mesh.

    Parameters
    ----------
    quad_mesh : PolyMesh, closed 2-manifold, all faces quads; its ``creases`` get the crease
        masks (:func:`_crease_limit_rows`).

    Returns
    -------
    L : (n, n) csr_matrix, ``L @ V`` are the limit positions (rows sum to 1).
    Tu, Tv : (n, n) csr_matrix, ``Tu @ V`` and ``Tv @ V`` are two limit tangents
        (rows sum to 0); ``cross(Tu @ V, Tv @ V)`` points outward. At a valence-4
        vertex without crease edges they are the derivatives of the limit surface with
        respect to the mesh's grid parameter (one edge = one unit) along the vertex's spoke
        0 and spoke 1; at other valences only their directions and the normal matter; at
        crease vertices and corners they span one side's tangent plane.

    Raises
    ------
    InvalidMeshError
        ``empty``, ``not_quads``, ``open`` or ``non_manifold`` (see ``_require_closed_quads``).
    """
    topo = _require_closed_quads(quad_mesh)
    fv = quad_mesh.face_vertices
    n = len(quad_mesh.vertices)
    spoke, valence, _ = spoke_order(quad_mesh, topo)
    vert = fv
    nxt = fv[topo.next_corner]
    diag = fv[topo.next_corner[topo.next_corner]]
    nv = valence[vert].astype(np.float64)
    denom = nv * (nv + 5.0)
    rows = np.concatenate([np.arange(n), vert, vert])
    cols = np.concatenate([np.arange(n), nxt, diag])
    vf = valence.astype(np.float64)
    self_w = np.where(vf > 0, vf / (vf + 5.0), 1.0)
    L = sp.csr_matrix((np.concatenate([self_w, 4.0 / denom, 1.0 / denom]), (rows, cols)),
                      shape=(n, n))
    ang = 2.0 * np.pi * spoke / nv
    ang1 = 2.0 * np.pi * (spoke + 1) / nv
    a_n = 1.0 + np.cos(2 * np.pi / nv) + np.cos(np.pi / nv) * np.sqrt(
        2.0 * (9.0 + np.cos(2 * np.pi / nv)))
    rc = np.concatenate([vert, vert])
    cc = np.concatenate([nxt, diag])
    Tu = sp.csr_matrix((np.concatenate([a_n * np.cos(ang), np.cos(ang) + np.cos(ang1)]) / 12.0,
                        (rc, cc)), shape=(n, n))
    Tv = sp.csr_matrix((np.concatenate([a_n * np.sin(ang), np.sin(ang) + np.sin(ang1)]) / 12.0,
                        (rc, cc)), shape=(n, n))
    crease = crease_edge_mask(topo, quad_mesh.creases)
    if crease.any():
        L, Tu, Tv = _crease_limit_rows(quad_mesh, topo, spoke, crease, L, Tu, Tv)
    return L, Tu, Tv


def _crease_limit_rows(quad_mesh, topo, spoke, crease, L, Tu, Tv):
    """``L, Tu, Tv`` with the rows of crease vertices and corners replaced.

    A vertex with two crease edges has the limit ``(e0 + 4 v + e1) / 6`` of the cubic
    B-spline crease curve; a corner (three or more) its own position; a dart (one) the
    limit mask of :func:`dart_limit_mask` (its crease edge's midpoint rule makes the smooth
    mask wrong by up to ~0.3% of a cage's size) and the smooth tangent masks (directions
    only). The limit surface has one tangent plane per side at crease vertices and corners; the tangents given are those of the side after the first crease spoke
    (counter-clockwise): ``Tu`` along that crease edge (``e - v``), ``Tv`` towards the mean of
    the far corners of that side's faces, so ``cross(Tu, Tv)`` is the outward normal of
    that side where it is planar (a direction only, not a derivative).
    """
    fv = quad_mesh.face_vertices
    n = len(quad_mesh.vertices)
    n_crease = vertex_crease_counts(topo, crease, n)
    sharp = n_crease >= 2
    rows_e = topo.edges[crease].reshape(-1)
    cols_e = topo.edges[crease][:, ::-1].reshape(-1)
    on_curve = n_crease[rows_e] == 2
    curve = sp.csr_matrix((np.full(on_curve.sum(), 1.0 / 6.0), (rows_e[on_curve], cols_e[on_curve])),
                          shape=(n, n))
    self_w = np.where(n_crease == 2, 4.0 / 6.0, 1.0)
    keep = sp.diags((~sharp).astype(np.float64))
    L_sharp = sp.diags(np.where(sharp, self_w, 0.0)) + curve
    dart = n_crease == 1
    keep_l = sp.diags((~sharp & ~dart).astype(np.float64))
    L = (keep_l @ L + L_sharp + _dart_rows(quad_mesh, topo, spoke, crease, dart)).tocsr()
    L.eliminate_zeros()
    # one side: the faces from the first crease spoke to the next one
    corner_crease = crease[topo.corner_edge]
    big = np.iinfo(np.int64).max
    first = np.full(n, big, dtype=np.int64)
    np.minimum.at(first, fv[corner_crease], spoke[corner_crease])
    later = corner_crease & (spoke > first[fv])
    second = np.full(n, big, dtype=np.int64)
    np.minimum.at(second, fv[later], spoke[later])
    corners = np.flatnonzero(sharp[fv])
    v = fv[corners]
    along = corners[spoke[corners] == first[v]]
    side = corners[(spoke[corners] >= first[v]) & (spoke[corners] < second[v])]
    side_size = np.bincount(fv[side], minlength=n).astype(np.float64)
    sharp_ids = np.flatnonzero(sharp)
    minus = sp.csr_matrix((np.full(len(sharp_ids), -1.0), (sharp_ids, sharp_ids)), shape=(n, n))
    Tu_sharp = minus + sp.csr_matrix((np.ones(len(along)), (fv[along], fv[topo.next_corner[along]])),
                                     shape=(n, n))
    diag = fv[topo.next_corner[topo.next_corner[side]]]
    Tv_sharp = minus + sp.csr_matrix((1.0 / side_size[fv[side]], (fv[side], diag)), shape=(n, n))
    Tu = (keep @ Tu + Tu_sharp).tocsr()
    Tv = (keep @ Tv + Tv_sharp).tocsr()
    Tu.eliminate_zeros()
    Tv.eliminate_zeros()
    return L, Tu, Tv


def _dart_rows(quad_mesh, topo, spoke, crease, dart):
    """(n, n) csr rows of :func:`dart_limit_mask` at the ``dart`` vertices ((n,) bool)."""
    fv = quad_mesh.face_vertices
    n = len(quad_mesh.vertices)
    valence = np.bincount(fv, minlength=n)
    corners = np.flatnonzero(dart[fv])
    v = fv[corners]
    crease_spoke = np.zeros(n, dtype=np.int64)
    along = corners[crease[topo.corner_edge[corners]]]
    crease_spoke[fv[along]] = spoke[along]
    k = np.mod(spoke[corners] - crease_spoke[v], valence[v])
    darts = np.flatnonzero(dart)
    top = int(valence.max())
    table = np.zeros((top + 1, 2 * top + 1))
    for m in np.unique(valence[darts]).tolist():
        table[m, :2 * m + 1] = dart_limit_mask(m)
    rows = np.concatenate([darts, v, v])
    cols = np.concatenate([darts, fv[topo.next_corner[corners]],
                           fv[topo.next_corner[topo.next_corner[corners]]]])
    vals = np.concatenate([table[valence[darts], 0], table[valence[v], 1 + k],
                           table[valence[v], 1 + valence[v] + k]])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


_DART_MASKS = {}


def dart_limit_mask(n):
    """Limit mask of a valence-``n`` dart (a vertex with one crease edge) of a quad mesh.

    The dart's one-ring (the vertex, its ``n`` spoke ends, the ``n`` far corners of its
    quads) maps to the next level's one-ring by a (2 n + 1, 2 n + 1) matrix of the crease
    rules (its crease edge's point is the midpoint); the limit mask is its left eigenvector
    of eigenvalue 1, summing to 1.

    Returns
    -------
    (2 n + 1,) float64 weights of the vertex, the spoke ends (spoke 0 is the crease) and
    the far corners (corner ``s`` between spokes ``s`` and ``s + 1``), counter-clockwise.
    """
    if n not in _DART_MASKS:
        s = np.arange(n)
        quads = np.stack([np.zeros(n, dtype=np.int64), 1 + s, 1 + n + s, 1 + (s + 1) % n],
                         axis=1)
        _, _, S, topo = subdivision_operator(quads.reshape(-1), np.arange(0, 4 * n + 1, 4),
                                             2 * n + 1, allow_open=True,
                                             creases=np.array([[0, 1]]))
        spoke_edges = topo.edge_index(np.zeros(n, dtype=np.int64), 1 + s)
        ring = np.concatenate([[0], 2 * n + 1 + n + spoke_edges, 2 * n + 1 + s])
        M = S[ring].toarray()
        values, vectors = np.linalg.eig(M.T)
        mask = np.real(vectors[:, np.argmin(np.abs(values - 1.0))])
        _DART_MASKS[n] = mask / mask.sum()
    return _DART_MASKS[n]


def limit_normals(quad_mesh):
    """(n, 3) float64 unit outward limit normals of every vertex of a closed quad mesh."""
    _, Tu, Tv = limit_matrices(quad_mesh)
    nrm = np.cross(Tu @ quad_mesh.vertices, Tv @ quad_mesh.vertices)
    return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def bspline_weights(t):
    """(p, 4) float64 uniform cubic B-spline basis values at local parameters ``t`` (p,)."""
    t = np.asarray(t, dtype=np.float64)
    s = 1.0 - t
    return np.stack([s ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1,
                     t ** 3], axis=-1) / 6.0


def corner_frame(u, v, corner):
    """Rotate face parameters so that ``corner`` (0..3, arrays) becomes the origin.

    Corner ``k``'s frame has its first axis along the edge to corner ``k + 1`` and its
    second axis along the edge to corner ``k - 1``. Returns (a, b) arrays.
    """
    a = np.select([corner == 0, corner == 1, corner == 2], [u, v, 1.0 - u], 1.0 - v)
    b = np.select([corner == 0, corner == 1, corner == 2], [v, 1.0 - u, 1.0 - v], u)
    return a, b


def _walk(topo, g, direction):
    """The half-edge of the neighbouring quad in ``direction`` (``"+a"``, ``"+b"``, ``"-a"`` or
    ``"-b"``) of the quads walked by half-edges ``g`` (corner = half-edge leaving it), in the
    same orientation."""
    nx, pv, tw = topo.next_corner, topo.prev_corner, topo.twin
    if direction == "+a":
        return nx[tw[nx[g]]]
    if direction == "+b":
        return tw[nx[nx[g]]]
    if direction == "-a":
        return pv[tw[pv[g]]]
    return nx[nx[tw[g]]]


def _corner_vertex(face_vertices, topo, g, la, lb):
    """Vertex at local corner (la, lb) in {0,1}^2 of the quad walked by half-edge g."""
    nx, pv = topo.next_corner, topo.prev_corner
    c = np.select([(la == 0) & (lb == 0), (la == 1) & (lb == 0), (la == 1) & (lb == 1)],
                  [g, nx[g], nx[nx[g]]], pv[g])
    return face_vertices[c]


def quad_stencils(quad_mesh, topo):
    """(m, 4, 4) int64 uniform bicubic B-spline stencil of every face of a closed quad mesh.

    ``stencil[f, a, b]`` is the vertex at grid position ``(a - 1, b - 1)`` of face ``f``'s
    frame (corner 0 at (0, 0), corner 1 at (1, 0), corner 3 at (0, 1)). Meaningful only for
    faces whose four corners have valence 4 (their limit is the bicubic B-spline of the
    stencil); other faces get whatever the walk meets.
    """
    fv = quad_mesh.face_vertices
    m = quad_mesh.n_faces
    g00 = 4 * np.arange(m, dtype=np.int64)
    faces = {}
    for i in (-1, 0, 1):
        gi = g00 if i == 0 else _walk(topo, g00, "+a" if i > 0 else "-a")
        for j in (-1, 0, 1):
            faces[i, j] = gi if j == 0 else _walk(topo, gi, "+b" if j > 0 else "-b")
    st = np.empty((m, 4, 4), dtype=np.int64)
    for a in range(-1, 3):
        i = min(max(a - 1, -1), 1)
        for b in range(-1, 3):
            j = min(max(b - 1, -1), 1)
            st[:, a + 1, b + 1] = _corner_vertex(fv, topo, faces[i, j], np.full(m, a - i),
                                                 np.full(m, b - j))
    return st


# ---------------------------------------------------------------- EV templates ----

def template_id(n, s, a, b, r=TEMPLATE_RADIUS):
    """Unique template point id of sector coordinates (s, a, b); a, b in -1..r."""
    s = np.asarray(s, dtype=np.int64).copy()
    a = np.asarray(a, dtype=np.int64).copy()
    b = np.asarray(b, dtype=np.int64).copy()
    neg_a = a < 0
    s[neg_a], a[neg_a], b[neg_a] = s[neg_a] + 1, b[neg_a], 1
    neg_b = b < 0
    s[neg_b], a[neg_b], b[neg_b] = s[neg_b] - 1, 1, a[neg_b]
    on_b_axis = (a == 0) & (b > 0)
    s[on_b_axis], a[on_b_axis], b[on_b_axis] = s[on_b_axis] + 1, b[on_b_axis], 0
    ids = 1 + np.mod(s, n) * r * (r + 1) + (a - 1) * (r + 1) + b
    return np.where((a == 0) & (b == 0), 0, ids)


def _template_grid(n, r=TEMPLATE_RADIUS):
    """All (s, a, b) with a in 1..r, b in 0..r (one per unique point except the centre)."""
    s, a, b = np.meshgrid(np.arange(n), np.arange(1, r + 1), np.arange(r + 1), indexing="ij")
    return s.reshape(-1), a.reshape(-1), b.reshape(-1)


_TEMPLATE_CACHE = {}


def template_matrix(n, r=TEMPLATE_RADIUS, crease_spokes=0):
    """(K, K) dense subdivision matrix of the radius-``r`` neighbourhood of a valence-``n`` EV.

    The neighbourhood is ``n`` sectors of ``r x r`` quads around the EV (what every
    EV looks like after two subdivision steps); row order is :func:`template_id`.
    Row ``i`` gives template point ``i`` one level finer, in the same sector
    coordinates, as exact Catmull-Clark combinations (valid for ``r >= 3``).
    ``crease_spokes`` : int, bit ``s`` set when spoke ``s`` (the edges from the centre
    along sector ``s``'s first axis) is a crease; the crease rules apply along it.
    """
    key = (n, r, int(crease_spokes))
    if key in _TEMPLATE_CACHE:
        return _TEMPLATE_CACHE[key]
    K = 1 + n * r * (r + 1)
    s, i, j = np.meshgrid(np.arange(n), np.arange(r), np.arange(r), indexing="ij")
    s, i, j = s.reshape(-1), i.reshape(-1), j.reshape(-1)
    quads = np.stack([template_id(n, s, i, j, r), template_id(n, s, i + 1, j, r),
                      template_id(n, s, i + 1, j + 1, r), template_id(n, s, i, j + 1, r)],
                     axis=1)
    n_faces = len(quads)
    creased = np.flatnonzero((int(crease_spokes) >> np.arange(n)) & 1)
    cs, ca = np.repeat(creased, r), np.tile(np.arange(r), len(creased))
    creases = np.stack([template_id(n, cs, ca, np.zeros_like(ca), r),
                        template_id(n, cs, ca + 1, np.zeros_like(ca), r)], axis=1)
    _, _, S, topo = subdivision_operator(quads.reshape(-1),
                                         np.arange(0, 4 * n_faces + 1, 4), K, allow_open=True,
                                         creases=creases if len(creases) else None)
    fs, fa, fb = _template_grid(n, r)
    fs = np.concatenate([[0], fs])
    fa = np.concatenate([[0], fa])
    fb = np.concatenate([[0], fb])
    a0, b0 = fa // 2, fb // 2
    a1, b1 = (fa + 1) // 2, (fb + 1) // 2
    vert = template_id(n, fs, a0, b0, r)
    edge = topo.edge_index(template_id(n, fs, a0, b0, r), template_id(n, fs, a1, b1, r))
    face = fs * r * r + a0 * r + b0
    fine = np.where((fa % 2 == 0) & (fb % 2 == 0), vert,
                    np.where((fa % 2 == 1) & (fb % 2 == 1), K + face, K + n_faces + edge))
    A = S[fine].toarray()
    _TEMPLATE_CACHE[key] = A
    return A


class LimitEvaluator:
    """Exact evaluation of the Catmull-Clark limit surface of a closed quad mesh.

    Parameters
    ----------
    quad_mesh : PolyMesh, closed 2-manifold, all quads. Faces are parameterised by
        ``(u, v)`` in ``[0, 1]^2`` with corner 0 at (0, 0), corner 1 at (1, 0),
        corner 2 at (1, 1), corner 3 at (0, 1).

    Notes
    -----
    The mesh is subdivided twice internally so that every EV is at least four edges
    from any other and every sub-quad has at most one EV corner.

    Crease edges (``quad_mesh.creases``) are evaluated exactly too. A work quad is
    *regular* when each corner is, for it: a valence-4 vertex without crease edges, a
    valence-4 vertex on a straight crease (two opposite crease edges, one of them a side of
    the quad), or a corner (three or more crease edges) whose two edges along the quad are
    creases. Its limit is then the bicubic B-spline of its 4 x 4 stencil with the points
    beyond each creased side replaced by the phantom points ``2 * crease - interior`` (as
    OpenSubdiv's boundary patches: the crease rules on one side of the crease equal the
    smooth rules on that reflected net). Any other corner (valence not 4, darts, crease
    vertices and corners with more faces on the quad's side) is treated as an EV: local
    subdivision templates with the crease rules along the creased spokes, and phantom points
    in the sub-quads next to a creased spoke.
    """

    WORK_LEVELS = 2

    def __init__(self, quad_mesh):
        _require_closed_quads(quad_mesh)
        self.hierarchy = build_hierarchy(quad_mesh, self.WORK_LEVELS)
        work = self.hierarchy.meshes[-1]
        self.work = work
        topo = mesh_topology(work.face_vertices, work.face_offsets, len(work.vertices))
        self.topo = topo
        self.spoke, self.valence, self.first = spoke_order(work, topo)
        L, _, _ = limit_matrices(work)
        self.work_limit = L @ work.vertices
        fv = work.face_vertices
        crease = crease_edge_mask(topo, work.creases)
        self.crease_sides = crease[topo.corner_edge].reshape(-1, 4)
        self.crease_spokes = np.zeros(len(work.vertices), dtype=np.int64)
        on = np.flatnonzero(crease[topo.corner_edge])
        np.add.at(self.crease_spokes, fv[on], np.left_shift(1, self.spoke[on]))
        irregular = ~self._regular_corners(crease).reshape(-1, 4)
        if (irregular.sum(axis=1) > 1).any():
            raise InternalError("a work quad has more than one extraordinary corner after "
                                f"{self.WORK_LEVELS} subdivisions")
        self.ev_corner = np.where(irregular.any(axis=1), irregular.argmax(axis=1), -1)
        self.stencils = quad_stencils(work, topo)
        self.ev_vertices = np.unique(fv[irregular.reshape(-1)])
        self._ev_slot = np.full(len(work.vertices), -1, dtype=np.int64)
        self._ev_levels = {}
        keys, kind = self._ev_kinds(self.ev_vertices)
        self._ev_keys = keys
        self._ev_kind = np.full(len(work.vertices), -1, dtype=np.int64)
        self._ev_kind[self.ev_vertices] = kind
        for index, key in enumerate(keys):
            evs = self.ev_vertices[kind == index]
            self._ev_slot[evs] = np.arange(len(evs))
            self._ev_levels[key] = [self._gather_templates(evs, key[0])]

    def _ev_kinds(self, vertices):
        """Template kinds of ``vertices`` ((p,) int64): the sorted distinct ``(valence, crease
        spoke bits)`` tuples, and the index of each vertex's among them ((p,) int64)."""
        pairs = np.stack([self.valence[vertices], self.crease_spokes[vertices]], axis=1)
        distinct, kind = np.unique(pairs.reshape(-1, 2), axis=0, return_inverse=True)
        return [tuple(int(x) for x in row) for row in distinct], kind.reshape(-1)

    def _regular_corners(self, crease):
        """(k,) bool: the vertex of every work corner is regular for the corner's quad (class
        notes)."""
        fv, topo = self.work.face_vertices, self.topo
        n_crease = vertex_crease_counts(topo, crease, len(self.work.vertices))[fv]
        valence = self.valence[fv]
        bits = self.crease_spokes[fv]
        smooth = (n_crease == 0) & (valence == 4)
        straight = (n_crease == 2) & (valence == 4) & ((bits == 0b0101) | (bits == 0b1010))
        both_sides = crease[topo.corner_edge] & crease[topo.corner_edge[topo.prev_corner]]
        return smooth | straight | ((n_crease >= 3) & both_sides)

    # -- topology walks on the work mesh (corner = half-edge leaving it) --
    def _move(self, g, direction):
        return _walk(self.topo, g, direction)

    def _corner_vertex(self, g, la, lb):
        return _corner_vertex(self.work.face_vertices, self.topo, g, la, lb)

    def _gather_templates(self, evs, n, r=TEMPLATE_RADIUS):
        """(len(evs), K, 3) float64 positions of the template points around EVs."""
        rot = self.topo.twin[self.topo.prev_corner]
        corners = np.empty((len(evs), n), dtype=np.int64)
        cur = self.first[evs]
        for s in range(n):
            corners[np.arange(len(evs)), self.spoke[cur]] = cur
            cur = rot[cur]
        K = 1 + n * r * (r + 1)
        ids = np.empty((len(evs), K), dtype=np.int64)
        ids[:, 0] = evs
        row_g = corners
        for i in range(r):
            g = row_g
            for j in range(r):
                for la in (0, 1):
                    for lb in (0, 1):
                        a, b = i + la, j + lb
                        if a == 0:
                            continue
                        tid = template_id(n, np.arange(n), np.full(n, a), np.full(n, b), r)
                        vid = self._corner_vertex(g, np.full(g.shape, la), np.full(g.shape, lb))
                        ids[:, tid] = vid
                g = self._move(g, "+b")
            row_g = self._move(row_g, "+a")
        return self.work.vertices[ids]

    def _ev_level(self, key, m):
        levels = self._ev_levels[key]
        if m >= len(levels):
            A = template_matrix(key[0], crease_spokes=key[1])
            while len(levels) <= m:
                levels.append(np.einsum("ij,ejk->eik", A, levels[-1]))
        return levels[m]

    def evaluate(self, face, u, v):
        """Exact limit points.

        Parameters
        ----------
        face : (p,) int64 face of the evaluator's mesh.
        u, v : (p,) float64 parameters in [0, 1].

        Returns
        -------
        (p, 3) float64 points on the limit surface.
        """
        face = np.asarray(face, dtype=np.int64).reshape(-1)
        u = np.clip(np.asarray(u, dtype=np.float64).reshape(-1), 0.0, 1.0)
        v = np.clip(np.asarray(v, dtype=np.float64).reshape(-1), 0.0, 1.0)
        for _ in range(self.WORK_LEVELS):
            hu, hv = u >= 0.5, v >= 0.5
            child = np.where(hu, np.where(hv, 2, 1), np.where(hv, 3, 0))
            a, b = corner_frame(u, v, child)
            face = 4 * face + child
            u, v = np.clip(2.0 * a, 0.0, 1.0), np.clip(2.0 * b, 0.0, 1.0)
        out = np.empty((len(face), 3))
        evc = self.ev_corner[face]
        reg = evc < 0
        plain = reg & ~self.crease_sides[face].any(axis=1)
        if plain.any():
            out[plain] = self._eval_regular(face[plain], u[plain], v[plain])
        sharp = reg & ~plain
        if sharp.any():
            out[sharp] = self._eval_crease_regular(face[sharp], u[sharp], v[sharp])
        if (~reg).any():
            idx = np.flatnonzero(~reg)
            c = evc[idx]
            a, b = corner_frame(u[idx], v[idx], c)
            corner = 4 * face[idx] + c
            ev = self.work.face_vertices[corner]
            out[idx] = self._eval_near_ev(ev, self.spoke[corner], a, b)
        return out

    def _eval_regular(self, face, u, v):
        """(p, 3) limit points of regular quads without creased sides: the bicubic B-spline
        of each quad's stencil."""
        from core.subdivision.patch_sums import bspline_patch_points

        return bspline_patch_points(u, v, self.stencils.reshape(-1, 16), face,
                                    self.work.vertices)

    def _eval_crease_regular(self, face, u, v):
        """(p, 3) limit points of regular quads with creased sides (phantom nets)."""
        P = self.work.vertices[self.stencils[face]]
        side = self.crease_sides[face]
        _reflect(P, side[:, 0], side[:, 2], side[:, 3], side[:, 1])
        w = bspline_weights(u)[:, :, None] * bspline_weights(v)[:, None, :]
        return np.einsum("pij,pijk->pk", w, P)

    def _eval_near_ev(self, ev, sector, a, b):
        from core.subdivision.patch_sums import bspline_patch_points

        out = np.empty((len(ev), 3))
        at_ev = (a <= 0.0) & (b <= 0.0)
        out[at_ev] = self.work_limit[ev[at_ev]]
        rest = np.flatnonzero(~at_ev)
        if not len(rest):
            return out
        a, b, ev, sector = a[rest], b[rest], ev[rest], sector[rest]
        _, e = np.frexp(np.maximum(a, b))
        m = (1 - e).astype(np.int64)
        A = np.ldexp(a, m)
        B = np.ldexp(b, m)
        i = np.minimum(np.floor(A), 1).astype(np.int64)
        j = np.minimum(np.floor(B), 1).astype(np.int64)
        kind = self._ev_kind[ev]
        res = np.empty((len(rest), 3))
        # the points of one template kind and level together, each group in index order
        group = kind * (int(m.max()) + 1) + m
        order = np.argsort(group, kind="stable")
        cuts = np.flatnonzero(np.diff(group[order])) + 1
        for sel in np.split(order, cuts):
            index, lev = int(kind[sel[0]]), int(m[sel[0]])
            key = self._ev_keys[index]
            n, bits = key
            table = _stencil_table(n)
            C = self._ev_level(key, lev)
            tid = table[sector[sel], i[sel], j[sel]]
            # the 4 x 4 nets as rows of the level's template points, all EVs of the kind
            nets = self._ev_slot[ev[sel]][:, None] * C.shape[1] + tid
            if not bits:
                res[sel] = bspline_patch_points(A[sel] - i[sel], B[sel] - j[sel], nets,
                                                np.arange(len(sel)), C.reshape(-1, 3))
                continue
            # sub-quads next to a creased spoke: phantom points beyond it
            pts = C.reshape(-1, 3)[nets].reshape(-1, 4, 4, 3)
            below = (j[sel] == 0) & ((bits >> sector[sel]) & 1).astype(bool)
            left = (i[sel] == 0) & ((bits >> ((sector[sel] + 1) % n)) & 1).astype(bool)
            none = np.zeros(len(sel), dtype=bool)
            _reflect(pts, below, none, left, none)
            w = (bspline_weights(A[sel] - i[sel])[:, :, None]
                 * bspline_weights(B[sel] - j[sel])[:, None, :]).reshape(-1, 16)
            res[sel] = np.einsum("pi,pik->pk", w, pts.reshape(-1, 16, 3))
        out[rest] = res
        return out


@functools.lru_cache(maxsize=None)
def _stencil_table(n):
    """(n, 2, 2, 16) template ids of the 4 x 4 stencil of sub-quad (i, j) of a sector (read-only:
    one table per valence ``n`` is kept)."""
    s = np.arange(n)[:, None, None, None, None]
    i = np.arange(2)[None, :, None, None, None]
    j = np.arange(2)[None, None, :, None, None]
    di = np.arange(-1, 3)[None, None, None, :, None]
    dj = np.arange(-1, 3)[None, None, None, None, :]
    shape = (n, 2, 2, 4, 4)
    ids = template_id(n, np.broadcast_to(s, shape).reshape(-1),
                       np.broadcast_to(i + di, shape).reshape(-1),
                       np.broadcast_to(j + dj, shape).reshape(-1))
    ids = ids.reshape(n, 2, 2, 16)
    ids.setflags(write=False)
    return ids


def _reflect(P, v_low, v_high, u_low, u_high):
    """Replace the points of 4 x 4 nets beyond creased sides by phantom points, in place.

    Parameters
    ----------
    P : (p, 4, 4, 3) nets ``P[:, a, b]`` of quads spanning ``a, b`` in 1..2.
    v_low, v_high, u_low, u_high : (p,) bool, the side ``v = 0`` (row ``b = 1``),
        ``v = 1``, ``u = 0`` (column ``a = 1``) or ``u = 1`` is a crease; the row or column
        beyond it becomes ``2 * crease - interior``. Rows first, then columns, so a corner
        between two creased sides gets the tensor-product reflection.
    """
    P[v_low, :, 0] = 2.0 * P[v_low, :, 1] - P[v_low, :, 2]
    P[v_high, :, 3] = 2.0 * P[v_high, :, 2] - P[v_high, :, 1]
    P[u_low, 0] = 2.0 * P[u_low, 1] - P[u_low, 2]
    P[u_high, 3] = 2.0 * P[u_high, 2] - P[u_high, 1]


def quad_mesh_of(mesh):
    """``mesh`` if it is all quads, else its first Catmull-Clark refinement (a PolyMesh)."""
    if (mesh.face_sizes == 4).all():
        return mesh
    return build_hierarchy(mesh, 1).meshes[1]


def vertex_limit_matrix(mesh):
    """(n, n) csr_matrix: row ``i`` gives the Catmull-Clark limit position of vertex ``i`` of
    ``mesh`` (a closed 2-manifold with faces of any size and its creases) from its vertices.

    One subdivision step keeps the vertices first and makes every face a quad, so the rows
    are those of :func:`limit_matrices` of the refined mesh times the step. (For positions
    only, ``core.quadmesh.limit_interpolation.vertex_limit_positions`` applies the two
    factors to the vertices one after the other.)
    """
    from core.subdivision.catmull_clark import subdivide

    fine, step = subdivide(mesh)
    return (limit_matrices(fine)[0] @ step)[:len(mesh.vertices)].tocsr()


def limit_volume(mesh, level=5):
    """Volume enclosed by the Catmull-Clark limit surface of a closed polygon mesh.

    The mesh is subdivided ``level`` times, every vertex is moved to its exact limit
    position (:func:`limit_matrices`), and the enclosed volume of the resulting quad
    mesh (divergence theorem) is extrapolated from levels ``level - 1`` and
    ``level`` (Richardson, the error is O(4^-level)).

    Parameters
    ----------
    mesh : PolyMesh, closed 2-manifold, faces outward.
    level : int >= 2

    Returns
    -------
    volume : float, in model units cubed.

    Raises
    ------
    ParameterError when ``level < 2``.
    """
    if level < 2:
        raise ParameterError(f"limit_volume needs level >= 2, got {level}")
    h = build_hierarchy(mesh, level)
    vols = []
    for lev in (level - 1, level):
        m = h.meshes[lev]
        L, _, _ = limit_matrices(m)
        vols.append(polymesh_volume(L @ m.vertices, m.face_vertices, m.face_offsets))
    return (4.0 * vols[1] - vols[0]) / 3.0

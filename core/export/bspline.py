# SPDX-License-Identifier: LGPL-2.1-or-later
"""Catmull-Clark limit surface -> bicubic B-spline patches (one per base quad).

Method
------
Patches (:mod:`core.export.patch_mesh`): one per base quad, whatever the other faces
are; a face with ``n != 4`` corners gives the ``n`` quads of its first Catmull-Clark
refinement. A base quad's side next to such a face is split at its midpoint into two
B-rep edges, so the B-rep stays conforming while the quad keeps one surface. The limit
surface is evaluated exactly on the base mesh (all quads) or on its level-1
refinement, where a base quad is its four level-1 quads.

On a patch the limit surface is a piecewise bicubic polynomial on the dyadic "graded"
grid with knots ``0, 2^-d, ..., 1/4, 1/2, 3/4, ..., 1 - 2^-d, 1``, C2 across every knot
line, except in the ``2^-d x 2^-d`` cells at extraordinary corners, where it is not
polynomial at all. So a clamped bicubic B-spline on that knot vector reproduces the
limit surface exactly outside those corner cells, and approximates it inside them (the
error shrinks with ``d``). A base quad whose corners have valence 4 and touch only
quads is one bicubic polynomial (the uniform B-spline of its 16-point 1-ring),
reproduced exactly by a single Bezier patch.

Knot vectors of base quads are per "edge ring" (strips of base quads crossing opposite
sides): a ring gets the graded knot vector if any of its quads is not regular, a
single Bezier span otherwise, so opposite sides of a quad carry the same knots and
neighbouring quads agree on every shared side. Patches of non-quad faces are graded in
both directions; the knots of half a graded side are a subset of the graded knots, so
the halves of a split side are represented exactly on them.

Poles are fitted to exact limit points (:class:`core.subdivision.limit.LimitEvaluator`)
at dyadic parameters: first every edge curve once (ends fixed at the B-rep vertices,
the pole next to an extraordinary end projected onto the exact limit tangent plane so
all patches share the normal there), written bit-identically into the patches that
use the whole curve as a side (a split side uses its parent side curve); then the
interior poles by a tensor-product least-squares fit with the boundary fixed. Where
the limit surface lies in the spline space the fit is exact. The shared vertices and
edges are returned as a :class:`core.export.brep_topology.BRepTopology`.
"""
import numpy as np
from scipy.interpolate import BSpline
from scipy.sparse.csgraph import connected_components
import scipy.sparse as sp

from core.export.brep_topology import BRepTopology, EdgeCurve
from core.export.patch_mesh import build_patch_mesh
from core.params import EXPORT_DEPTH, check_export_depth
from core.subdivision.catmull_clark import mesh_topology
from core.subdivision.limit import LimitEvaluator, corner_frame, limit_matrices
from core.tolerances import CONTACT
from core.types import BSplinePatch, PatchSet

BEZIER = 0
GRADED = 1


# ------------------------------------------------------------------ knots ---

def graded_knots(depth):
    """(2 depth + 1,) float64 distinct knots 0, 2^-depth, ..., 1/2, ..., 1 - 2^-depth, 1.

    All values are dyadic, so ``1 - t`` is exact and the vector is bit-symmetric.
    """
    small = np.ldexp(1.0, -np.arange(depth, 0, -1))
    return np.concatenate([[0.0], small, 1.0 - small[::-1][1:], [1.0]])


def knot_vector(kind, depth):
    """(knots, mults) of a knot kind (BEZIER or GRADED) in OpenCascade form."""
    if kind == BEZIER:
        return np.array([0.0, 1.0]), np.array([4, 4], dtype=np.int64)
    k = graded_knots(depth)
    mults = np.ones(len(k), dtype=np.int64)
    mults[0] = mults[-1] = 4
    return k, mults


def full_knots(knots, mults):
    """Flat knot vector (sum(mults),) from distinct knots and multiplicities."""
    return np.repeat(np.asarray(knots, dtype=np.float64), np.asarray(mults, dtype=np.int64))


def basis_matrix(knots, mults, t, deriv=0, degree=3):
    """(len(t), n_poles) float64 values (or derivatives) of the B-spline basis at ``t``."""
    tk = full_knots(knots, mults)
    n = len(tk) - degree - 1
    t = np.asarray(t, dtype=np.float64)
    return BSpline(tk, np.eye(n), degree, extrapolate=True)(t, nu=deriv)


def sample_params(kind, depth, per_span=2):
    """(s,) float64 dyadic fitting parameters: each knot span split into ``per_span``."""
    knots = knot_vector(kind, depth)[0]
    frac = np.arange(per_span) / per_span
    inner = (knots[:-1, None] + frac[None, :] * np.diff(knots)[:, None]).reshape(-1)
    return np.concatenate([inner, [1.0]])


# ----------------------------------------------------------- patch mesh ---

def _edge_param(corner, t):
    """Face parameters (u, v) of the point ``t`` along the edge leaving local corner."""
    one = np.ones_like(t)
    zero = np.zeros_like(t)
    u = np.select([corner == 0, corner == 1, corner == 2], [t, one, 1.0 - t], zero)
    v = np.select([corner == 0, corner == 1, corner == 2], [zero, t, one], 1.0 - t)
    return u, v


class _PatchContext:
    """Topology and exact-evaluation data shared by fitting and measurement."""

    def __init__(self, base, depth):
        self.base = base
        self.depth = int(depth)
        pm = build_patch_mesh(base)
        self.pm = pm
        self.level = pm.level
        self.face_of_patch = pm.face_of_patch
        work = pm.work
        self.evaluator = LimitEvaluator(work)
        L, Tu, Tv = limit_matrices(work)
        self.limit = L @ work.vertices
        nrm = np.cross(Tu @ work.vertices, Tv @ work.vertices)
        self.normal = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        self.is_ev = np.bincount(work.face_vertices, minlength=len(work.vertices)) != 4
        mesh = pm.mesh
        self.topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
        n_edges = len(self.topo.edges)
        first = np.full(n_edges, -1, dtype=np.int64)
        c = np.arange(len(mesh.face_vertices), dtype=np.int64)
        first[self.topo.corner_edge[::-1]] = c[::-1]
        self.edge_corner = first
        self._knot_kinds(base)
        lo, hi = work.vertices.min(axis=0), work.vertices.max(axis=0)
        limit_lo, limit_hi = self.limit.min(axis=0), self.limit.max(axis=0)
        self.bbox_diagonal = float(np.linalg.norm(np.maximum(hi, limit_hi)
                                                  - np.minimum(lo, limit_lo)))

    def _knot_kinds(self, base):
        """Knot kind of every base edge (per ring of base quads) and of every patch.

        A base quad is regular when its four corners have valence 4 and touch only
        quads (its limit surface is then one bicubic polynomial); a ring of quads
        (joined through opposite sides) gets the graded knots if any of its quads is
        not regular. Patches of non-quad faces are graded in both directions.
        """
        pm = self.pm
        fv, fo = base.face_vertices, base.face_offsets
        topo = mesh_topology(fv, fo, len(base.vertices))
        self.base_topo = topo
        quad = base.face_sizes == 4
        corner_quad = quad[topo.face_of_corner]
        valence = np.bincount(fv, minlength=len(base.vertices))
        irregular_vertex = valence != 4
        irregular_vertex[fv[~corner_quad]] = True
        qf = np.flatnonzero(quad)
        qc = fo[qf][:, None] + np.arange(4)
        quad_edges = topo.corner_edge[qc]
        pairs = np.concatenate([quad_edges[:, [0, 2]], quad_edges[:, [1, 3]]])
        n_edges = len(topo.edges)
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                              shape=(n_edges, n_edges))
        _, ring = connected_components(graph, directed=False)
        graded_ring = np.zeros(ring.max() + 1, dtype=bool)
        irregular_quad = irregular_vertex[fv[qc]].any(axis=1)
        graded_ring[ring[quad_edges[irregular_quad].reshape(-1)]] = True
        self.base_edge_kind = np.where(graded_ring[ring], GRADED, BEZIER)
        k = pm.n_patches
        self.kind_u = np.full(k, GRADED, dtype=np.int64)
        self.kind_v = np.full(k, GRADED, dtype=np.int64)
        self.face_has_ev = np.ones(k, dtype=bool)
        whole = np.flatnonzero(pm.whole_quad)
        corner = fo[pm.face_of_patch[whole]][:, None] + np.arange(4)
        self.kind_u[whole] = self.base_edge_kind[topo.corner_edge[corner[:, 0]]]
        self.kind_v[whole] = self.base_edge_kind[topo.corner_edge[corner[:, 3]]]
        self.face_has_ev[whole] = irregular_vertex[fv[corner]].any(axis=1)
        self.quad_corner = np.full((k, 4), -1, dtype=np.int64)
        self.quad_corner[whole] = corner

    def evaluate(self, patch, u, v):
        """(p, 3) exact limit points of patches ``patch`` (p,) at parameters (p,)."""
        patch = np.asarray(patch, dtype=np.int64)
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
        face = self.pm.work_face[patch]
        if self.level == 1:
            whole = self.pm.whole_quad[patch]
            child = np.where(u >= 0.5, np.where(v >= 0.5, 2, 1), np.where(v >= 0.5, 3, 0))
            a, b = corner_frame(u, v, child)
            face = np.where(whole, face + child, face)
            u = np.where(whole, 2.0 * a, u)
            v = np.where(whole, 2.0 * b, v)
        return self.evaluator.evaluate(face, u, v)


# ------------------------------------------------------------------ fitting ---

def _side_samples(ctx, kind, patch, corner):
    """Basis matrix and exact limit samples along patch sides.

    Parameters
    ----------
    kind : BEZIER or GRADED; patch, corner : (c,) int64 patch and local corner (0..3)
        whose side (towards corner + 1) is sampled.

    Returns
    -------
    B : (t, n_poles) basis of ``kind`` at the sample parameters.
    X : (c, t, 3) exact limit points.
    """
    knots, mults = knot_vector(kind, ctx.depth)
    t = sample_params(kind, ctx.depth, per_span=4 if kind == BEZIER else 2)
    u, v = _edge_param(np.repeat(corner, len(t)), np.tile(t, len(patch)))
    X = ctx.evaluate(np.repeat(patch, len(t)), u, v).reshape(len(patch), len(t), 3)
    return basis_matrix(knots, mults, t), X


def _fit_with_ends(ctx, B, X, start, end, start_pos, end_pos):
    """Least-squares curve poles (c, n, 3) through samples ``X`` (c, t, 3).

    The ends are fixed at ``start_pos``/``end_pos`` (c, 3); where the end vertex
    ``start``/``end`` (c,) of the work mesh is extraordinary, the pole next to it is
    projected onto the exact limit tangent plane, so all patches there share it.
    """
    Q = np.empty((len(X), B.shape[1], 3))
    Q[:, 0] = start_pos
    Q[:, -1] = end_pos
    R = X - B[None, :, 0, None] * Q[:, None, 0] - B[None, :, -1, None] * Q[:, None, -1]
    Q[:, 1:-1] = np.einsum("it,etk->eik", np.linalg.pinv(B[:, 1:-1]), R)
    for end_idx, near_idx, vert in ((0, 1, start), (-1, -2, end)):
        ev = ctx.is_ev[vert]
        nrm = ctx.normal[vert[ev]]
        d = Q[ev, near_idx] - Q[ev, end_idx]
        Q[ev, near_idx] -= np.sum(d * nrm, axis=1, keepdims=True) * nrm
    return Q


def _fit_side_curves(ctx, vertex_pos):
    """Curves of the base edges next to a base quad, each fitted once on a quad side.

    Returns
    -------
    dict base edge -> (start vertex, end vertex, kind, (n, 3) poles).
    """
    pm, bt = ctx.pm, ctx.base_topo
    corners = ctx.quad_corner.reshape(-1)
    has = corners >= 0
    patch = np.repeat(np.arange(pm.n_patches), 4)[has]
    local = np.tile(np.arange(4), pm.n_patches)[has]
    corners = corners[has]
    edge, pick = np.unique(bt.corner_edge[corners], return_index=True)
    patch, local, corners = patch[pick], local[pick], corners[pick]
    a = ctx.base.face_vertices[corners]
    b = ctx.base.face_vertices[bt.next_corner[corners]]
    sides = {}
    for kind in (BEZIER, GRADED):
        sel = np.flatnonzero(ctx.base_edge_kind[edge] == kind)
        if not len(sel):
            continue
        B, X = _side_samples(ctx, kind, patch[sel], local[sel])
        Q = _fit_with_ends(ctx, B, X, a[sel], b[sel], vertex_pos[a[sel]], vertex_pos[b[sel]])
        for e, start, end, poles in zip(edge[sel].tolist(), a[sel].tolist(), b[sel].tolist(), Q):
            sides[e] = (start, end, kind, poles)
    return sides


def _fit_edge_curves(ctx):
    """Vertex positions and the (n_poles, 3) poles of every patch-mesh edge.

    Base edges between two quads take their side curve. A split base edge next to a
    quad takes the two halves of the quad's side curve, re-expressed exactly on the
    graded knots (the halves' knots are a subset), so the quad's face and the small
    patch on the other side meet within rounding. The other edges (inside non-quad
    faces, or between two of them) are fitted to the limit surface directly.

    Returns
    -------
    vertex_pos : (n_work_vertices, 3) float64 B-rep vertex positions: exact limit
        points, except midpoints of split edges next to a quad (the side curve at 1/2).
    edge_poles : list of (n, 3) arrays per patch-mesh edge, running from the start
        vertex of its representative corner (``ctx.edge_corner``).
    sides : dict base edge -> (start, end, kind, poles), from :func:`_fit_side_curves`.
    """
    pm, topo = ctx.pm, ctx.topo
    fv = pm.mesh.face_vertices
    n_base = len(ctx.base.vertices)
    vertex_pos = ctx.limit.copy()
    sides = _fit_side_curves(ctx, vertex_pos)
    rep = ctx.edge_corner
    start, end = fv[rep], fv[topo.next_corner[rep]]
    base_edge = pm.base_edge[rep]
    whole_use = pm.whole_quad[topo.face_of_corner[np.stack([rep, topo.twin[rep]], axis=1)]]
    is_half = (start >= n_base) | (end >= n_base)
    edge_poles = [None] * len(rep)
    for e in np.flatnonzero(whole_use.all(axis=1)).tolist():
        a, _, _, Q = sides[int(base_edge[e])]
        edge_poles[e] = Q if start[e] == a else Q[::-1]
    half = np.flatnonzero(is_half & whole_use.any(axis=1))
    if len(half):
        mid = np.where(start[half] >= n_base, start[half], end[half])
        for i, e in enumerate(half.tolist()):
            a, _, kind, Q = sides[int(base_edge[e])]
            vertex_pos[mid[i]] = basis_matrix(*knot_vector(kind, ctx.depth), [0.5])[0] @ Q
        gk, gm = knot_vector(GRADED, ctx.depth)
        t = sample_params(GRADED, ctx.depth)
        X = np.empty((len(half), len(t), 3))
        for i, e in enumerate(half.tolist()):
            a, _, kind, Q = sides[int(base_edge[e])]
            s = t if start[e] < n_base else 1.0 - t  # from the base vertex to the midpoint
            corner = start[e] if start[e] < n_base else end[e]
            along = 0.5 * s if corner == a else 1.0 - 0.5 * s
            X[i] = basis_matrix(*knot_vector(kind, ctx.depth), along) @ Q
        Qh = _fit_with_ends(ctx, basis_matrix(gk, gm, t), X, start[half], end[half],
                            vertex_pos[start[half]], vertex_pos[end[half]])
        for i, e in enumerate(half.tolist()):
            edge_poles[e] = Qh[i]
    rest = np.flatnonzero([q is None for q in edge_poles])
    if len(rest):
        patch = topo.face_of_corner[rep[rest]]
        local = rep[rest] - pm.mesh.face_offsets[patch]
        B, X = _side_samples(ctx, GRADED, patch, local)
        Q = _fit_with_ends(ctx, B, X, start[rest], end[rest], vertex_pos[start[rest]],
                           vertex_pos[end[rest]])
        for i, e in enumerate(rest.tolist()):
            edge_poles[e] = Q[i]
    return vertex_pos, edge_poles, sides


def _boundary_rows(ctx, edge_poles, sides, patches):
    """Boundary curves of ``patches`` in patch orientation: list of 4 (len(patches), n, 3).

    Row ``k`` runs from patch corner ``k`` to ``k + 1``: the base side curve for a whole
    quad, else the patch-mesh edge curve.
    """
    pm, topo = ctx.pm, ctx.topo
    fv = pm.mesh.face_vertices
    out = []
    for k in range(4):
        rows = []
        for p in patches.tolist():
            if pm.whole_quad[p]:
                c = ctx.quad_corner[p, k]
                a, _, _, Q = sides[int(ctx.base_topo.corner_edge[c])]
                rows.append(Q if ctx.base.face_vertices[c] == a else Q[::-1])
            else:
                c = pm.patch_corner[p, k]
                e = topo.corner_edge[c]
                Q = edge_poles[e]
                rows.append(Q if fv[ctx.edge_corner[e]] == fv[c] else Q[::-1])
        out.append(np.stack(rows))
    return out


def _fit_patches(ctx, edge_poles, sides):
    m = ctx.pm.n_patches
    patches = [None] * m
    for ku in (BEZIER, GRADED):
        for kv in (BEZIER, GRADED):
            faces = np.flatnonzero((ctx.kind_u == ku) & (ctx.kind_v == kv))
            if not len(faces):
                continue
            knu, mu = knot_vector(ku, ctx.depth)
            knv, mv = knot_vector(kv, ctx.depth)
            su = sample_params(ku, ctx.depth, per_span=4 if ku == BEZIER else 2)
            sv = sample_params(kv, ctx.depth, per_span=4 if kv == BEZIER else 2)
            Bu = basis_matrix(knu, mu, su)
            Bv = basis_matrix(knv, mv, sv)
            nu, nv = Bu.shape[1], Bv.shape[1]
            rows = _boundary_rows(ctx, edge_poles, sides, faces)
            P = np.zeros((len(faces), nu, nv, 3))
            P[:, :, 0] = rows[0]
            P[:, -1, :] = rows[1]
            P[:, :, -1] = rows[2][:, ::-1]
            P[:, 0, :] = rows[3][:, ::-1]
            U, V = np.meshgrid(su, sv, indexing="ij")
            Au = np.linalg.pinv(Bu[:, 1:-1])
            Av = np.linalg.pinv(Bv[:, 1:-1])
            for chunk in np.array_split(np.arange(len(faces)), max(1, len(faces) // 256)):
                f = faces[chunk]
                X = ctx.evaluate(np.repeat(f, U.size), np.tile(U.reshape(-1), len(f)),
                                 np.tile(V.reshape(-1), len(f)))
                X = X.reshape(len(f), len(su), len(sv), 3)
                Pb = P[chunk]
                R = X - _tensor_apply(Bu, Pb, Bv)
                P[chunk, 1:-1, 1:-1] = _tensor_apply(Au, R, Av)
            for idx, f in enumerate(faces.tolist()):
                patches[f] = BSplinePatch(P[idx], knu, mu, knv, mv)
    return patches


def _topology(ctx, vertex_pos, edge_poles):
    """The BRepTopology of the patch mesh: one vertex per used work vertex, one edge
    per patch-mesh edge, one use per patch-mesh corner."""
    pm, topo = ctx.pm, ctx.topo
    fv = pm.mesh.face_vertices
    used = np.unique(fv)
    index = np.full(len(vertex_pos), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    rep = ctx.edge_corner
    edge_vertices = np.stack([index[fv[rep]], index[fv[topo.next_corner[rep]]]], axis=1)
    curves = []
    for Q in edge_poles:
        kind = BEZIER if len(Q) == 4 else GRADED
        knots, mults = knot_vector(kind, ctx.depth)
        curves.append(EdgeCurve(np.ascontiguousarray(Q), knots, mults))
    corner = np.arange(len(fv))
    reversed_use = fv[rep[topo.corner_edge]] != fv
    uv = np.stack([pm.corner_uv, pm.corner_uv[topo.next_corner]], axis=1)
    uv[reversed_use] = uv[reversed_use][:, ::-1]
    return BRepTopology(vertex_pos[used], edge_vertices, curves, topo.face_of_corner[corner],
                        topo.corner_edge.astype(np.int64), reversed_use, uv)


def limit_surface_patches(base, depth=EXPORT_DEPTH, measure=True):
    """Bicubic B-spline patches of the Catmull-Clark limit surface of ``base``.

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold polygon mesh (validated by the caller).
    depth : int in 1..MAX_EXPORT_DEPTH, grading depth ``d``: corner cells at extraordinary
        vertices are ``2^-d`` of a patch wide (default ``EXPORT_DEPTH``).
    measure : bool, if True fill ``info`` with the approximation and continuity
        figures (costs about as much as the fit).

    Returns
    -------
    PatchSet
        ``patches[i]`` is face ``i`` of the patch mesh
        (:func:`core.export.patch_mesh.build_patch_mesh`): one per
        base quad, ``n`` per base face with ``n != 4`` corners; ``face_of_patch[i]`` is
        its base face; ``topology`` holds the shared B-rep vertices and edges (a quad
        side next to a non-quad face is two edges). ``d/du x d/dv`` points outward.
        ``info`` holds ``patch_level``, ``n_patches``, ``patches_per_base_face``,
        ``n_split_base_edges``, ``n_extraordinary_vertices``, ``n_graded_patches``,
        ``n_poles``, ``depth``, ``bbox_diagonal`` and, if ``measure``, ``max_error``,
        ``max_error_rel``, ``max_ev_error``, ``max_ev_error_rel``,
        ``normal_jump_max_deg``, ``normal_jump_p95_deg``, ``normal_jump_ev_max_deg``.

    Raises
    ------
    ParameterError when ``depth`` is not an integer in 1..MAX_EXPORT_DEPTH.
    """
    check_export_depth(depth)
    ctx = _PatchContext(base, depth)
    vertex_pos, edge_poles, sides = _fit_edge_curves(ctx)
    patches = _fit_patches(ctx, edge_poles, sides)
    topology = _topology(ctx, vertex_pos, edge_poles)
    sizes = base.face_sizes
    per_face = np.bincount(ctx.face_of_patch, minlength=base.n_faces)
    info = {
        "patch_level": int(ctx.level),
        "n_patches": len(patches),
        "patches_per_base_face": {str(n): float(per_face[sizes == n].mean())
                                  for n in np.unique(sizes).tolist()},
        "n_split_base_edges": int(len(np.unique(ctx.base_topo.corner_edge[
            sizes[ctx.base_topo.face_of_corner] != 4]))),
        "n_extraordinary_vertices": int(ctx.is_ev[np.unique(ctx.pm.mesh.face_vertices)].sum()),
        "n_graded_patches": int(((ctx.kind_u == GRADED) | (ctx.kind_v == GRADED)).sum()),
        "n_poles": int(sum(p.poles.shape[0] * p.poles.shape[1] for p in patches)),
        "depth": int(depth),
        "bbox_diagonal": ctx.bbox_diagonal,
    }
    result = PatchSet(patches, ctx.face_of_patch, info, topology)
    if measure:
        info.update(patch_deviation(result, base, _context=ctx))
        info.update(normal_jumps(result, base, _context=ctx))
    return result


# ---------------------------------------------------------------- evaluation ---

def evaluate_patches(patches, u, v, du=0, dv=0):
    """Points (or partial derivatives) of patches sharing one knot layout.

    Parameters
    ----------
    patches : list of BSplinePatch with identical knots and multiplicities.
    u, v : (s,) float64 parameters, evaluated on every patch.
    du, dv : derivative orders.

    Returns
    -------
    (len(patches), s, 3) float64
    """
    p0 = patches[0]
    Bu = basis_matrix(p0.u_knots, p0.u_mults, u, du)
    Bv = basis_matrix(p0.v_knots, p0.v_mults, v, dv)
    P = np.stack([p.poles for p in patches])
    n, nu, nv, _ = P.shape
    tmp = np.matmul(np.swapaxes(P, 1, 2).reshape(n, nv, nu * 3).swapaxes(1, 2), Bv.T)
    tmp = tmp.reshape(n, nu, 3, len(v))
    return np.einsum("si,niks->nsk", Bu, tmp)


def evaluate_patch_points(patches, face, u, v, du=0, dv=0, chunk=4096):
    """Points (or partial derivatives) of any patches at one parameter pair each.

    Parameters
    ----------
    patches : list of BSplinePatch (any knot layouts).
    face : (p,) int64 patch of each point; u, v : (p,) float64 parameters.
    du, dv : derivative orders.
    chunk : int, points evaluated together (bounds memory on graded patches).

    Returns
    -------
    (p, 3) float64
    """
    face = np.asarray(face, dtype=np.int64)
    out = np.empty((len(face), 3))
    for g in _layout_groups(patches):
        p0 = patches[g[0]]
        slot = np.full(len(patches), -1, dtype=np.int64)
        slot[g] = np.arange(len(g))
        idx = np.flatnonzero(slot[face] >= 0)
        if not len(idx):
            continue
        P = np.stack([patches[i].poles for i in g])
        for part in np.array_split(idx, max(1, len(idx) // chunk)):
            Bu = basis_matrix(p0.u_knots, p0.u_mults, u[part], du, p0.degree_u)
            Bv = basis_matrix(p0.v_knots, p0.v_mults, v[part], dv, p0.degree_v)
            rows = np.einsum("pi,pijk->pjk", Bu, P[slot[face[part]]])
            out[part] = np.einsum("pj,pjk->pk", Bv, rows)
    return out


def evaluate_patch_grid(patches, su, sv, du=0, dv=0):
    """(len(patches), len(su), len(sv), 3) points of same-layout patches on a grid."""
    p0 = patches[0]
    Bu = basis_matrix(p0.u_knots, p0.u_mults, su, du)
    Bv = basis_matrix(p0.v_knots, p0.v_mults, sv, dv)
    return _tensor_apply(Bu, np.stack([p.poles for p in patches]), Bv)


def _tensor_apply(A, P, B):
    """(n, a, b, 3) = A @ P[n, :, :, k] @ B.T for every patch n and coordinate k."""
    n, nu, nv, _ = P.shape
    tmp = np.matmul(A, P.reshape(n, nu, nv * 3)).reshape(n, A.shape[0], nv, 3)
    return np.matmul(np.swapaxes(tmp, 2, 3), B.T).swapaxes(2, 3)


def _layout_groups(patches):
    groups = {}
    for i, p in enumerate(patches):
        key = (p.u_knots.tobytes(), p.u_mults.tobytes(), p.v_knots.tobytes(),
               p.v_mults.tobytes())
        groups.setdefault(key, []).append(i)
    return [np.array(g, dtype=np.int64) for g in groups.values()]


def _measure_params(patch_knots, per_span=3, depth_extra=4):
    """Parameters in every span plus geometric points into the end spans."""
    k = np.asarray(patch_knots, dtype=np.float64)
    frac = np.arange(per_span) / per_span
    t = (k[:-1, None] + frac[None, :] * np.diff(k)[:, None]).reshape(-1)
    first = k[1]
    geo = first * np.ldexp(1.0, -np.arange(1, depth_extra + 1))
    geo = np.concatenate([geo, 0.75 * geo])
    return np.unique(np.concatenate([t, [1.0], geo, 1.0 - geo]))


def patch_deviation(patchset, base, dense="ev", _context=None):
    """Largest distance between patches and the exact limit surface at equal parameters.

    Patch points are compared with exact limit points at the same (u, v), which
    bounds the geometric distance from above.

    Parameters
    ----------
    patchset : PatchSet from :func:`limit_surface_patches` for ``base``.
    base : PolyMesh
    dense : ``"ev"`` (default) samples patches with an extraordinary corner in every
        knot span and geometrically into their end spans, and the other patches on
        a 5 x 5 grid (they are exact); ``"all"`` samples every patch densely.

    Returns
    -------
    dict with ``max_error`` (model units), ``max_error_rel`` (fraction of the bounding
    box diagonal), ``max_ev_error`` / ``max_ev_error_rel`` over patches with an
    extraordinary corner (0 if none), and ``rms_error``.
    """
    ctx = _context or _PatchContext(base, 1)
    patches = patchset.patches
    worst = np.zeros(len(patches))
    sq_sum, count = 0.0, 0
    dense_mask = ctx.face_has_ev if dense == "ev" else np.ones(len(patches), dtype=bool)
    for g in _layout_groups(patches):
        p0 = patches[g[0]]
        for is_dense in (True, False):
            sub = g[dense_mask[g] == is_dense]
            if not len(sub):
                continue
            if is_dense:
                su, sv = _measure_params(p0.u_knots), _measure_params(p0.v_knots)
            else:
                su = sv = np.linspace(0.0, 1.0, 5)
            U, V = np.meshgrid(su, sv, indexing="ij")
            U, V = U.reshape(-1), V.reshape(-1)
            for chunk in np.array_split(sub, max(1, len(sub) * len(U) // 200000)):
                S = evaluate_patch_grid([patches[i] for i in chunk], su, sv)
                S = S.reshape(len(chunk), -1, 3)
                X = ctx.evaluate(np.repeat(chunk, len(U)), np.tile(U, len(chunk)),
                                 np.tile(V, len(chunk))).reshape(S.shape)
                d = np.linalg.norm(S - X, axis=2)
                worst[chunk] = d.max(axis=1)
                sq_sum += float(np.sum(d ** 2))
                count += d.size
    diag = ctx.bbox_diagonal
    ev_worst = float(worst[ctx.face_has_ev].max()) if ctx.face_has_ev.any() else 0.0
    return {
        "max_error": float(worst.max()),
        "max_error_rel": float(worst.max() / diag),
        "max_ev_error": ev_worst,
        "max_ev_error_rel": ev_worst / diag,
        "rms_error": float(np.sqrt(sq_sum / max(count, 1))),
    }


def normal_jumps(patchset, base, samples=None, _context=None):
    """Angles between the two patches' normals along every shared B-rep edge.

    Parameters
    ----------
    patchset : PatchSet from :func:`limit_surface_patches` for ``base`` (its
        ``topology``, or whole shared sides when it has none).
    base : PolyMesh
    samples : optional (s,) parameters along each edge in [0, 1]; default: the
        measuring parameters of a graded knot vector (dense near both ends) on edges
        with an extraordinary end, 9 even ones elsewhere.

    Returns
    -------
    dict with ``normal_jump_max_deg``, ``normal_jump_p95_deg`` (over all samples on
    all edges) and ``normal_jump_ev_max_deg`` (edges with an extraordinary end).
    """
    from core.export.brep_topology import topology_from_sides

    ctx = _context or _PatchContext(base, 1)
    topo = patchset.topology or topology_from_sides(patchset.patches)
    n_edges = len(topo.edge_curves)
    uses = np.argsort(topo.use_edge, kind="stable").reshape(n_edges, 2)
    ends = topo.vertices[topo.edge_vertices]
    ev_points = ctx.limit[ctx.is_ev]
    ev_edge = np.zeros(n_edges, dtype=bool)
    if len(ev_points):
        from scipy.spatial import cKDTree

        near = cKDTree(ev_points).query(ends.reshape(-1, 3))[0].reshape(n_edges, 2)
        ev_edge = (near <= CONTACT * ctx.bbox_diagonal).any(axis=1)
    if samples is None:
        dense_t = _measure_params(graded_knots(max(ctx.depth, EXPORT_DEPTH)))
        plain_t = np.linspace(0.0, 1.0, 9)
    else:
        dense_t = plain_t = np.asarray(samples, dtype=np.float64)
    angles, ev_angles = [], []
    for mask, t in ((ev_edge, dense_t), (~ev_edge, plain_t)):
        if not mask.any():
            continue
        pair = uses[mask]
        normals = []
        for side in range(2):
            u = pair[:, side]
            uv = topo.use_uv[u, 0, None, :] + t[None, :, None] * (topo.use_uv[u, 1]
                                                                  - topo.use_uv[u, 0])[:, None]
            face = np.repeat(topo.use_face[u], len(t))
            U, V = uv[..., 0].reshape(-1), uv[..., 1].reshape(-1)
            Su = evaluate_patch_points(patchset.patches, face, U, V, du=1)
            Sv = evaluate_patch_points(patchset.patches, face, U, V, dv=1)
            n = np.cross(Su, Sv)
            normals.append(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300))
        ang = np.degrees(np.arccos(np.clip(np.sum(normals[0] * normals[1], axis=1), -1.0, 1.0)))
        angles.append(ang)
        if mask is ev_edge:
            ev_angles.append(ang)
    ang = np.concatenate(angles)
    ev_ang = np.concatenate(ev_angles) if ev_angles else np.zeros(1)
    return {
        "normal_jump_max_deg": float(ang.max()),
        "normal_jump_p95_deg": float(np.percentile(ang, 95)),
        "normal_jump_ev_max_deg": float(ev_ang.max()),
    }


# --------------------------------------------------------------- tessellation ---

def _tessellation_params(patch_knots, resolution):
    """Every knot span split into ceil(span * resolution) equal parts (symmetric, exact
    on dyadic knots for power-of-two ``resolution``)."""
    k = np.asarray(patch_knots, dtype=np.float64)
    parts = np.maximum(1, np.ceil(np.diff(k) * resolution)).astype(np.int64)
    pieces = [k[i] + (k[i + 1] - k[i]) * np.arange(p) / p for i, p in enumerate(parts)]
    return np.concatenate(pieces + [[1.0]])


def tessellate_patches(patchset, resolution=16, weld_tolerance=1e-9):
    """Watertight triangle mesh of a PatchSet.

    Each patch is sampled on a grid (every knot span split into
    ``ceil(span * resolution)`` parts); neighbouring patches sharing a whole side share
    its knots, so their boundary samples coincide and are welded. A quad side split
    next to a non-quad face (mixed cages) is sampled differently on its two sides, so
    there the result is watertight only up to T-junctions.

    Parameters
    ----------
    patchset : PatchSet
    resolution : int, samples per unit of patch parameter (about ``2 resolution**2``
        triangles per patch).
    weld_tolerance : float, relative to the bounding-box diagonal of the samples.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (t, 3) int64, counter-clockwise seen from outside.
    """
    from scipy.spatial import cKDTree

    pts, tris = [], []
    base = 0
    for g in _layout_groups(patchset.patches):
        p0 = patchset.patches[g[0]]
        su = _tessellation_params(p0.u_knots, resolution)
        sv = _tessellation_params(p0.v_knots, resolution)
        S = evaluate_patch_grid([patchset.patches[i] for i in g], su, sv)
        a, b = len(su), len(sv)
        idx = np.arange(a * b).reshape(a, b)
        c00, c10 = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
        c11, c01 = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        local = np.concatenate([np.stack([c00, c10, c11], 1), np.stack([c00, c11, c01], 1)])
        offs = base + a * b * np.arange(len(g))
        tris.append((local[None] + offs[:, None, None]).reshape(-1, 3))
        pts.append(S.reshape(-1, 3))
        base += a * b * len(g)
    P = np.concatenate(pts)
    T = np.concatenate(tris)
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    pairs = cKDTree(P).query_pairs(weld_tolerance * diag, output_type="ndarray")
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                          shape=(len(P), len(P)))
    _, label = connected_components(graph, directed=False)
    uniq, first = np.unique(label, return_index=True)
    V = P[first]
    F = np.searchsorted(uniq, label)[T]
    keep = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    return V, F[keep]


def enclosed_volume(patches, chunk=64):
    """Signed volume enclosed by a closed patch set (divergence theorem).

    ``V = 1/3 sum_patches int (S - c) . (S_u x S_v) du dv`` with ``c`` the mean corner,
    by Gauss-Legendre quadrature with 5 nodes per knot span, exact for bicubic
    patches (the integrand has degree 8 in each parameter).

    Parameters
    ----------
    patches : list of BSplinePatch of degree <= 3, closed as a set.
    chunk : int, patches evaluated together.

    Returns
    -------
    float, model units cubed; positive when ``d/du x d/dv`` points outward.
    """
    nodes, weights = np.polynomial.legendre.leggauss(5)
    centre = np.mean([p.poles[0, 0] for p in patches], axis=0)

    def rule(knots):
        a, b = knots[:-1, None], knots[1:, None]
        return ((0.5 * (a + b) + 0.5 * (b - a) * nodes).reshape(-1),
                (0.5 * (b - a) * weights).reshape(-1))

    total = 0.0
    for g in _layout_groups(patches):
        p0 = patches[g[0]]
        su, wu = rule(p0.u_knots)
        sv, wv = rule(p0.v_knots)
        for part in np.array_split(g, max(1, len(g) // chunk)):
            sel = [patches[i] for i in part]
            S = evaluate_patch_grid(sel, su, sv) - centre
            normal = np.cross(evaluate_patch_grid(sel, su, sv, 1, 0),
                              evaluate_patch_grid(sel, su, sv, 0, 1))
            total += float(np.einsum("i,nijk,nijk,j->", wu, S, normal, wv))
    return total / 3.0

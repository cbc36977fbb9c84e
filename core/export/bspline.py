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

from core.export.brep_topology import BRepTopology, EdgeCurve
from core.export.bspline_basis import (BEZIER, GRADED, basis_matrix, knot_vector, sample_params,
                                      tensor_apply)
from core.export.bspline_measure import normal_jumps, patch_deviation
from core.export.patch_context import PatchContext
from core.forked import Ahead
from core.params import EXPORT_DEPTH, check_export_depth
from core.types import BSplinePatch, PatchSet


def _edge_param(corner, t):
    """Face parameters (u, v) of the point ``t`` along the edge leaving local corner."""
    one = np.ones_like(t)
    zero = np.zeros_like(t)
    u = np.select([corner == 0, corner == 1, corner == 2], [t, one, 1.0 - t], zero)
    v = np.select([corner == 0, corner == 1, corner == 2], [zero, t, one], 1.0 - t)
    return u, v


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
    ``start``/``end`` (c,) of the work mesh is extraordinary and on no crease, the pole next
    to it is projected onto the exact limit tangent plane, so all patches there share it. At a
    vertex on a crease nothing is projected: its limit surface has one tangent plane per
    side, and in sectors of a wide angle the crease rules leave it without a well-defined
    one (the secant normal of such a sector keeps turning as the parameter offset shrinks).
    """
    Q = np.empty((len(X), B.shape[1], 3))
    Q[:, 0] = start_pos
    Q[:, -1] = end_pos
    R = X - B[None, :, 0, None] * Q[:, None, 0] - B[None, :, -1, None] * Q[:, None, -1]
    Q[:, 1:-1] = np.einsum("it,etk->eik", np.linalg.pinv(B[:, 1:-1]), R)
    for end_idx, near_idx, vert in ((0, 1, start), (-1, -2, end)):
        ev = ctx.is_ev[vert] & ~ctx.on_crease[vert]
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
                R = X - tensor_apply(Bu, Pb, Bv)
                P[chunk, 1:-1, 1:-1] = tensor_apply(Au, R, Av)
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
    ctx = PatchContext(base, depth)
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
        # the normal jumps on another core while the deviation is measured here
        jumps = Ahead(normal_jumps, result, base, None, ctx)
        try:
            info.update(patch_deviation(result, base, context=ctx))
            info.update(jumps.result() or normal_jumps(result, base, context=ctx))
        finally:
            jumps.cancel()  # ends the child where the deviation raised
    return result

# SPDX-License-Identifier: LGPL-2.1-or-later
"""How close B-spline patches are to the Catmull-Clark limit surface they were fitted to, and
how smoothly they meet: the largest deviation at equal parameters and the normal jumps
along shared edges (the figures of ``limit_surface_patches(..., measure=True)``).
"""
import numpy as np

from core.export.bspline_basis import (evaluate_patch_grid, evaluate_patch_points, graded_knots,
                                      layout_groups)
from core.export.patch_context import PatchContext
from core.params import EXPORT_DEPTH
from core.tolerances import CONTACT


def _measure_params(patch_knots, per_span=3, depth_extra=4):
    """Parameters in every span plus geometric points into the end spans."""
    k = np.asarray(patch_knots, dtype=np.float64)
    frac = np.arange(per_span) / per_span
    t = (k[:-1, None] + frac[None, :] * np.diff(k)[:, None]).reshape(-1)
    first = k[1]
    geo = first * np.ldexp(1.0, -np.arange(1, depth_extra + 1))
    geo = np.concatenate([geo, 0.75 * geo])
    return np.unique(np.concatenate([t, [1.0], geo, 1.0 - geo]))


PROJECTION_STEPS = 3
"""Gauss-Newton steps of :func:`_closest_in_face`."""
REFINE_FRACTION = 0.1
"""Patch points farther than this fraction of the largest distance (per batch) from their
limit point are moved to the nearest limit point (the largest distance is what is reported;
the others keep an upper bound)."""


def _closest_in_face(ctx, face, u, v, points, steps=PROJECTION_STEPS, eps=1e-6):
    """(k, 3) limit points of quads ``face`` (k,) near ``points`` (k, 3): Gauss-Newton steps
    from the parameters ``(u, v)`` (k,) towards the closest point within the quad (parameters
    clamped to [0, 1], derivatives by one-sided differences of ``eps``); a step that does not
    bring the point closer is not taken, so the result is never farther than the start."""
    best = ctx.evaluate(face, u, v)
    dist = np.linalg.norm(best - points, axis=1)
    for _ in range(steps):
        hu = np.where(u + eps <= 1.0, eps, -eps)
        hv = np.where(v + eps <= 1.0, eps, -eps)
        Xu = (ctx.evaluate(face, u + hu, v) - best) / hu[:, None]
        Xv = (ctx.evaluate(face, u, v + hv) - best) / hv[:, None]
        r = points - best
        a, b, c = (np.einsum("ij,ij->i", Xu, Xu), np.einsum("ij,ij->i", Xu, Xv),
                   np.einsum("ij,ij->i", Xv, Xv))
        ru, rv = np.einsum("ij,ij->i", Xu, r), np.einsum("ij,ij->i", Xv, r)
        det = a * c - b * b
        ok = det > 1e-12 * np.maximum(a * c, 1e-300)
        safe = np.where(ok, det, 1.0)
        nu = np.clip(u + np.where(ok, (c * ru - b * rv) / safe, 0.0), 0.0, 1.0)
        nv = np.clip(v + np.where(ok, (a * rv - b * ru) / safe, 0.0), 0.0, 1.0)
        X = ctx.evaluate(face, nu, nv)
        d = np.linalg.norm(X - points, axis=1)
        better = d < dist
        u, v = np.where(better, nu, u), np.where(better, nv, v)
        best[better], dist[better] = X[better], d[better]
    return best


def patch_deviation(patchset, base, dense="ev", context=None, target_params=None):
    """Largest distance between patches and the exact limit surface.

    Patch points are compared with exact limit points at the same (u, v) or, with
    ``target_params``, at those parameters (moved to the nearest limit point in the quad
    where they are far); either bounds the geometric distance from above.

    Parameters
    ----------
    patchset : PatchSet from :func:`core.export.bspline.limit_surface_patches` for ``base``.
    base : PolyMesh
    dense : ``"ev"`` (default) samples patches with an extraordinary corner in every
        knot span and geometrically into their end spans, and the other patches on
        a 5 x 5 grid (they are exact); ``"all"`` samples every patch densely.
    context : the ``PatchContext`` of ``base`` when the caller has it (the fit does), else
        None (one is built).
    target_params : None (equal parameters) or a function ``(face, u, v) -> (u', v')`` of
        (k,) arrays: the limit parameters each patch point is compared with (the G1
        export's warped parameters, :mod:`core.export.corner_warp`); where that distance
        exceeds :data:`REFINE_FRACTION` of the largest, the limit point then moves to the
        closest one in the same quad (:func:`_closest_in_face`). Any limit point bounds the
        distance to the limit surface from above.

    Returns
    -------
    dict with ``max_error`` (model units), ``max_error_rel`` (fraction of the bounding
    box diagonal), ``max_ev_error`` / ``max_ev_error_rel`` over patches with an
    extraordinary corner (0 if none), and ``rms_error``.
    """
    ctx = context or PatchContext(base, 1)
    patches = patchset.patches
    worst = np.zeros(len(patches))
    sq_sum, count = 0.0, 0
    dense_mask = ctx.face_has_ev if dense == "ev" else np.ones(len(patches), dtype=bool)
    for g in layout_groups(patches):
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
                face = np.repeat(chunk, len(U))
                Uc, Vc = np.tile(U, len(chunk)), np.tile(V, len(chunk))
                if target_params is None:
                    X = ctx.evaluate(face, Uc, Vc).reshape(S.shape)
                else:
                    Uw, Vw = (a.reshape(-1) for a in target_params(face, Uc, Vc))
                    X = ctx.evaluate(face, Uw, Vw)
                    P = S.reshape(-1, 3)
                    d0 = np.linalg.norm(X - P, axis=1)
                    far = d0 > REFINE_FRACTION * d0.max()
                    X[far] = _closest_in_face(ctx, face[far], Uw[far], Vw[far], P[far])
                    X = X.reshape(S.shape)
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


def normal_jumps(patchset, base, samples=None, context=None, ev_vertex=None):
    """Angles between the two patches' normals along every shared B-rep edge.

    Parameters
    ----------
    patchset : PatchSet from :func:`core.export.bspline.limit_surface_patches` for ``base`` (its
        ``topology``, or whole shared sides when it has none).
    base : PolyMesh
    samples : optional (s,) parameters along each edge in [0, 1]; default: the
        measuring parameters of a graded knot vector (dense near both ends) on edges
        with an extraordinary end, 9 even ones elsewhere.
    context : the ``PatchContext`` of ``base``, or None (as :func:`patch_deviation`).
    ev_vertex : optional (nv,) bool per B-rep vertex of the topology, True at an
        extraordinary vertex; default: the B-rep vertices that lie on the exact limit point of
        an extraordinary vertex (the graded export's vertices do; fitted ones need this).

    Returns
    -------
    dict with ``normal_jump_max_deg``, ``normal_jump_p95_deg`` (over all samples on
    all edges but the crease edges, where the normal may jump) and
    ``normal_jump_ev_max_deg`` (edges with an extraordinary end), and
    ``normal_jump_crease_edges``: the B-rep edges left out.
    """
    from core.export.brep_topology import topology_from_sides

    ctx = context or PatchContext(base, 1)
    topo = patchset.topology or topology_from_sides(patchset.patches)
    n_edges = len(topo.edge_curves)
    uses = np.argsort(topo.use_edge, kind="stable").reshape(n_edges, 2)
    ends = topo.vertices[topo.edge_vertices]
    ev_points = ctx.limit[ctx.is_ev]
    ev_edge = np.zeros(n_edges, dtype=bool)
    if ev_vertex is not None:
        ev_edge = np.asarray(ev_vertex, dtype=bool)[topo.edge_vertices].any(axis=1)
    elif len(ev_points):
        from scipy.spatial import cKDTree

        near = cKDTree(ev_points).query(ends.reshape(-1, 3))[0].reshape(n_edges, 2)
        ev_edge = (near <= CONTACT * ctx.bbox_diagonal).any(axis=1)
    crease = ctx.crease_edge if patchset.topology is not None else np.zeros(n_edges, bool)
    if samples is None:
        dense_t = _measure_params(graded_knots(max(ctx.depth, EXPORT_DEPTH)))
        plain_t = np.linspace(0.0, 1.0, 9)
    else:
        dense_t = plain_t = np.asarray(samples, dtype=np.float64)
    angles, ev_angles = [], []
    for mask, t, at_ev in ((ev_edge & ~crease, dense_t, True),
                           (~ev_edge & ~crease, plain_t, False)):
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
        if at_ev:
            ev_angles.append(ang)
    ang = np.concatenate(angles) if angles else np.zeros(1)
    ev_ang = np.concatenate(ev_angles) if ev_angles else np.zeros(1)
    return {
        "normal_jump_max_deg": float(ang.max()),
        "normal_jump_p95_deg": float(np.percentile(ang, 95)),
        "normal_jump_ev_max_deg": float(ev_ang.max()),
        "normal_jump_crease_edges": int(crease.sum()),
    }

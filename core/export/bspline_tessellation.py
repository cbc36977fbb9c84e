# SPDX-License-Identifier: LGPL-2.1-or-later
"""B-spline patch sets as triangle meshes, and the volume they enclose.

:func:`tessellate_patches` samples every patch on its knot spans and welds the shared
boundary samples; :func:`enclosed_volume` integrates the divergence theorem exactly with
Gauss-Legendre quadrature.
"""
import numpy as np
from scipy.sparse.csgraph import connected_components
import scipy.sparse as sp

from core.export.bspline_basis import basis_matrix, evaluate_patch_grid, layout_groups
from core.tolerances import CONTACT


def _tessellation_params(patch_knots, resolution):
    """Every knot span split into ceil(span * resolution) equal parts (symmetric, exact
    on dyadic knots for power-of-two ``resolution``)."""
    k = np.asarray(patch_knots, dtype=np.float64)
    parts = np.maximum(1, np.ceil(np.diff(k) * resolution)).astype(np.int64)
    pieces = [k[i] + (k[i + 1] - k[i]) * np.arange(p) / p for i, p in enumerate(parts)]
    return np.concatenate(pieces + [[1.0]])


def tessellate_patches(patchset, resolution=16, weld_tolerance=CONTACT):
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
    weld_tolerance : float, relative to the bounding-box diagonal of the samples (default
        ``core.tolerances.CONTACT``).

    Returns
    -------
    vertices : (n, 3) float64
    faces : (t, 3) int64, counter-clockwise seen from outside.
    """
    from scipy.spatial import cKDTree

    pts, tris = [], []
    base = 0
    for g in layout_groups(patchset.patches):
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

    ``V = sum_patches int (S_z - c_z) (S_u x S_v)_z du dv`` (the field ``(0, 0, z - c_z)``,
    of divergence 1) with ``c`` the mean corner, by Gauss-Legendre quadrature with 5 nodes
    per knot span, exact for bicubic patches (the integrand has degree 8 in each parameter).

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
    for g in layout_groups(patches):
        p0 = patches[g[0]]
        su, wu = rule(p0.u_knots)
        sv, wv = rule(p0.v_knots)
        # the basis and its first derivative in u and in v (only z and the normal's z
        # component are needed: two of the three coordinates of each derivative)
        Bu = [basis_matrix(p0.u_knots, p0.u_mults, su, order) for order in (0, 1)]
        Bv = [basis_matrix(p0.v_knots, p0.v_mults, sv, order) for order in (0, 1)]
        for part in np.array_split(g, max(1, len(g) // chunk)):
            P = np.stack([patches[i].poles for i in part])
            x, y, z = P[..., 0], P[..., 1], P[..., 2]
            height = Bu[0] @ z @ Bv[0].T - centre[2]
            normal_z = ((Bu[1] @ x @ Bv[0].T) * (Bu[0] @ y @ Bv[1].T)
                        - (Bu[1] @ y @ Bv[0].T) * (Bu[0] @ x @ Bv[1].T))
            total += float(np.einsum("i,nij,nij,j->", wu, height, normal_z, wv))
    return total

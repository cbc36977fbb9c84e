# SPDX-License-Identifier: LGPL-2.1-or-later
"""Bicubic B-spline patches: knot vectors, basis matrices and evaluation.

The knot kinds of :mod:`core.export.bspline`'s patches (a single Bezier span, or the graded
dyadic knots ``0, 2^-d, ..., 1/2, ..., 1 - 2^-d, 1``), their basis matrices (scipy's
``BSpline`` on the identity), and the points and derivatives of ``core.types.BSplinePatch``
lists: on a shared parameter grid, or one parameter pair per point. The fit, the
measurement, the tessellation and the B-rep checks all evaluate through here.
"""
import numpy as np
from scipy.interpolate import BSpline

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
    for g in layout_groups(patches):
        p0 = patches[g[0]]
        slot = np.full(len(patches), -1, dtype=np.int64)
        slot[g] = np.arange(len(g))
        idx = np.flatnonzero(slot[face] >= 0)
        if not len(idx):
            continue
        P = np.stack([patches[i].poles for i in g])
        for part in np.array_split(idx, max(1, len(idx) // chunk)):
            iu, wu = _support(basis_matrix(p0.u_knots, p0.u_mults, u[part], du, p0.degree_u),
                              p0.degree_u)
            iv, wv = _support(basis_matrix(p0.v_knots, p0.v_mults, v[part], dv, p0.degree_v),
                              p0.degree_v)
            local = P[slot[face[part]][:, None, None], iu[:, :, None], iv[:, None, :]]
            out[part] = np.einsum("pa,pb,pabk->pk", wu, wv, local)
    return out


def _support(B, degree):
    """The ``degree + 1`` basis functions that can be nonzero at each parameter (those of its
    knot span, a contiguous run) of a basis matrix ``B`` (p, n): their indices (p, degree + 1)
    int64 and values (p, degree + 1), so a point costs (degree + 1)^2 poles, not all of them."""
    first = np.minimum(np.argmax(B != 0.0, axis=1), B.shape[1] - degree - 1)
    index = first[:, None] + np.arange(degree + 1)
    return index, np.take_along_axis(B, index, axis=1)


def evaluate_patch_grid(patches, su, sv, du=0, dv=0):
    """(len(patches), len(su), len(sv), 3) points of same-layout patches on a grid."""
    p0 = patches[0]
    Bu = basis_matrix(p0.u_knots, p0.u_mults, su, du)
    Bv = basis_matrix(p0.v_knots, p0.v_mults, sv, dv)
    return tensor_apply(Bu, np.stack([p.poles for p in patches]), Bv)


def tensor_apply(A, P, B):
    """(n, a, b, 3) = A @ P[n, :, :, k] @ B.T for every patch n and coordinate k."""
    n, nu, nv, _ = P.shape
    tmp = np.matmul(A, P.reshape(n, nu, nv * 3)).reshape(n, A.shape[0], nv, 3)
    return np.matmul(np.swapaxes(tmp, 2, 3), B.T).swapaxes(2, 3)


def layout_groups(patches):
    """Index arrays (int64) of the patches sharing one knot layout (u and v knots and
    multiplicities), in order of first appearance."""
    groups = {}
    for i, p in enumerate(patches):
        key = (p.u_knots.tobytes(), p.u_mults.tobytes(), p.v_knots.tobytes(),
               p.v_mults.tobytes())
        groups.setdefault(key, []).append(i)
    return [np.array(g, dtype=np.int64) for g in groups.values()]

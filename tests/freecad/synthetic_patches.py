# SPDX-License-Identifier: LGPL-2.1-or-later
"""Hand-built closed PatchSets for the B-rep tests (no subdivision involved).

Every patch is a clamped bicubic B-spline with one interior knot per direction
(knots 0, 0.5, 1 with multiplicities 4, 1, 4, so 5 x 5 poles). The poles of all
patches are taken from one shared table of unique points, indexed by integer
lattice coordinates, so neighbouring patches get bit-identical boundary poles.
"""
import numpy as np
from scipy.interpolate import BSpline

from core.types import BSplinePatch, PatchSet

_KNOTS = np.array([0.0, 0.5, 1.0])
_MULTS = np.array([4, 1, 4], dtype=np.int64)
# Greville abscissae of the clamped knot vector 0,0,0,0,.5,1,1,1,1: poles placed at
# these parameters reproduce a linear (affine) parametrisation exactly.
_GREVILLE = np.array([0.0, 1.0 / 6.0, 0.5, 5.0 / 6.0])


def _lattice_coordinates(m):
    """(4m+1,) float64 coordinates in [-1, 1] of the pole lattice along one cube edge."""
    k = np.arange(4 * m + 1)
    return -1.0 + 2.0 * (k // 4 + _GREVILLE[k % 4]) / m


def cube_patch_lattice(m):
    """Integer lattice indices of the poles of a cube covered by 6 m^2 patches.

    Returns
    -------
    idx : (6 m^2, 5, 5, 3) int64
        Lattice index (i, j, k) of every pole; ``d/du x d/dv`` points outward.
    """
    n = 4 * m
    local = np.arange(5)
    out = []
    for axis in range(3):
        b, c = (axis + 1) % 3, (axis + 2) % 3
        for sign in (1, -1):
            u_axis, v_axis = (b, c) if sign > 0 else (c, b)
            for pu in range(m):
                for pv in range(m):
                    idx = np.empty((5, 5, 3), dtype=np.int64)
                    idx[..., axis] = n if sign > 0 else 0
                    idx[..., u_axis] = (4 * pu + local)[:, None]
                    idx[..., v_axis] = (4 * pv + local)[None, :]
                    out.append(idx)
    return np.stack(out)


def lattice_patchset(m, point_map=None, half_size=1.0):
    """Closed PatchSet over a cube of ``6 m^2`` bicubic patches.

    Parameters
    ----------
    m : int
        Patches per cube edge.
    point_map : callable or None
        Maps (p, 3) float64 points on the cube [-1, 1]^3 to (p, 3) new positions.
        Applied once per unique pole, so shared boundary poles stay bit-identical.
    half_size : float
        Half the cube edge length before ``point_map``.
    """
    coords = _lattice_coordinates(m)
    idx = cube_patch_lattice(m)
    flat = idx.reshape(-1, 3)
    unique, inverse = np.unique(flat, axis=0, return_inverse=True)
    points = coords[unique]
    if point_map is not None:
        points = point_map(points)
    points = np.ascontiguousarray(points * half_size, dtype=np.float64)
    poles = points[inverse.reshape(-1)].reshape(idx.shape[:3] + (3,))
    patches = [BSplinePatch(p.copy(), _KNOTS.copy(), _MULTS.copy(), _KNOTS.copy(), _MULTS.copy())
               for p in poles]
    return PatchSet(patches, np.arange(len(patches), dtype=np.int64))


def superellipsoid_map(exponent=4.0, radius=1.0):
    """Radial map of the cube surface onto ``|x|^e + |y|^e + |z|^e = radius^e``."""
    def apply(points):
        norm = np.sum(np.abs(points) ** exponent, axis=1) ** (1.0 / exponent)
        return points * (radius / norm)[:, None]
    return apply


def _basis(knots, mults, degree, t):
    """(len(t), n) values and derivatives of all B-spline basis functions at ``t``."""
    full = np.repeat(knots, mults)
    n = len(full) - degree - 1
    spline = BSpline(full, np.eye(n), degree)
    return spline(t), spline.derivative()(t)


def divergence_volume(patchset, gauss_points=6):
    """Volume enclosed by a closed PatchSet, computed without OpenCascade.

    Uses the divergence theorem, V = 1/3 sum over patches of the integral of
    p . (p_u x p_v), with Gauss-Legendre quadrature on every knot span. With 6 points
    per span the bicubic integrand (degree 8 per direction) is integrated exactly.
    """
    x, w = np.polynomial.legendre.leggauss(gauss_points)
    total = 0.0
    for patch in patchset.patches:
        tu, wu = _span_rule(patch.u_knots, x, w)
        tv, wv = _span_rule(patch.v_knots, x, w)
        bu, dbu = _basis(patch.u_knots, patch.u_mults, patch.degree_u, tu)
        bv, dbv = _basis(patch.v_knots, patch.v_mults, patch.degree_v, tv)
        p = np.einsum("ia,abk,jb->ijk", bu, patch.poles, bv)
        pu = np.einsum("ia,abk,jb->ijk", dbu, patch.poles, bv)
        pv = np.einsum("ia,abk,jb->ijk", bu, patch.poles, dbv)
        integrand = np.einsum("ijk,ijk->ij", p, np.cross(pu, pv))
        total += wu @ integrand @ wv
    return total / 3.0


def _span_rule(knots, x, w):
    """Gauss-Legendre nodes and weights on every span between consecutive knots."""
    a, b = knots[:-1, None], knots[1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * x[None, :]
    weights = 0.5 * (b - a) * w[None, :]
    return t.ravel(), weights.ravel()

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Points of bicubic uniform B-spline patches, one point per parameter pair, compiled.

The exact limit evaluation (:class:`core.subdivision.limit.LimitEvaluator`) ends, for every
point, in the tensor-product B-spline of a 4 x 4 net of control points: those of a regular
quad's stencil, or of a regular sub-quad of a local subdivision template near an
extraordinary vertex. The export's deviation check evaluates millions of such points; one
compiled loop over them computes the sixteen weights and the sum without the ``(p, 16)`` and
``(p, 16, 3)`` arrays of a vectorised form. The function is cached on disk like those of
:mod:`core.box_tree` (:mod:`core.precompile` compiles it at set-up).
"""
import numpy as np

from core.compiled import keeps_interrupts, numba


@keeps_interrupts
def bspline_patch_points(u, v, nets, net, points):
    """(p, 3) float64 points of bicubic uniform B-spline patches.

    Parameters
    ----------
    u, v : (p,) float64 local parameters in [0, 1] of each point in its patch's span.
    nets : (q, 16) int64 control-point indices of the patches, row-major 4 x 4
        (``nets[k, 4 a + b]`` weighted by the ``a``-th basis function of ``u`` and the ``b``-th
        of ``v``).
    net : (p,) int64 the row of ``nets`` of each point.
    points : (n, 3) float64 control points.

    Returns
    -------
    (p, 3) float64 ``sum_ab N_a(u) N_b(v) points[nets[net, 4 a + b]]``, ``N`` the uniform cubic
    B-spline basis (:func:`core.subdivision.limit.bspline_weights`).
    """
    return _patch_points(np.ascontiguousarray(u, dtype=np.float64),
                         np.ascontiguousarray(v, dtype=np.float64),
                         np.ascontiguousarray(nets, dtype=np.int64).reshape(-1, 16),
                         np.ascontiguousarray(net, dtype=np.int64),
                         np.ascontiguousarray(points, dtype=np.float64))


@numba.njit(inline="always")
def _basis(t, out):
    """The four uniform cubic B-spline basis values at ``t`` into ``out`` ((4,) float64)."""
    s = 1.0 - t
    t2 = t * t
    t3 = t2 * t
    out[0] = s * s * s / 6.0
    out[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    out[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    out[3] = t3 / 6.0


@numba.njit(cache=True, nogil=True)
def _patch_points(u, v, nets, net, points):
    out = np.empty((len(u), 3))
    wu = np.empty(4)
    wv = np.empty(4)
    for k in range(len(u)):
        _basis(u[k], wu)
        _basis(v[k], wv)
        row = net[k]
        x = y = z = 0.0
        for a in range(4):
            for b in range(4):
                w = wu[a] * wv[b]
                q = nets[row, 4 * a + b]
                x += w * points[q, 0]
                y += w * points[q, 1]
                z += w * points[q, 2]
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z
    return out

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Where a polynomial patch should meet the Catmull-Clark limit near a special vertex: the
limit's own parameters re-scaled radially around each patch corner.

Method
------
Near an extraordinary vertex (and near a crease vertex whose sectors are not two faces each),
the limit surface's distance from the vertex's limit point grows like ``r ** gamma`` in the
parameter distance ``r`` along a spoke, with ``gamma = -log2(lambda)`` for the subdominant
eigenvalue ``lambda`` of the subdivision there (``gamma > 1`` at valence 3, ``< 1`` from
valence 5 on; 1 at a regular vertex). A polynomial patch grows like ``r``, so matching the
limit at equal parameters asks it to follow a parameter speed it cannot have, and the fit
spends its freedom on the parameterisation instead of the shape. Matched instead at the
*warped* parameter ``r' = R (r / R) ** (1 / gamma)`` (``R`` = :data:`WARP_RADIUS`, same
direction from the corner), the limit points sample the same surface with a speed a cubic can
follow, and the fit's error becomes a distance between shapes.

``gamma`` comes from the eigenvalues of the local subdivision matrix of each special vertex's
kind (:func:`vertex_growth`), one value per vertex, so the two patches of an edge are fitted
to the same limit points along it, and the fit stays a fixed linear map of the cage. The disks
of radius :data:`WARP_RADIUS` around the four corners do not overlap, and the warp is the
identity on a disk's rim and at its corner, so patch corners and the middle of every side
keep their exact limit points.
"""
import numpy as np

from core.export.brep_topology import CORNER_UV
from core.subdivision.limit import spoke_order, template_matrix

WARP_RADIUS = 0.5
"""Parameter distance from a corner within which the targets are warped (half a side: the
four corners' disks touch but do not overlap)."""
GROWTH_RANGE = (0.5, 2.0)
"""Exponents are clipped to this range (a guard: Catmull-Clark's smooth vertices have exponents
from about 1.29 at valence 3 down towards 0.61 for large valences)."""


def vertex_growth(quads, topo, crease, special):
    """Growth exponents ``gamma = -log2(lambda)`` of the limit surface at every vertex.

    ``lambda`` is the largest eigenvalue magnitude below 1 of the local subdivision matrix
    of the vertex's kind (valence and crease spokes,
    :func:`core.subdivision.limit.template_matrix`): the rate at which the ring around the
    vertex contracts towards its limit point, so the limit's distance from that point grows
    like ``r ** gamma`` in the parameter distance ``r``. A function of the topology only, so
    the fit stays linear in the cage.

    Parameters
    ----------
    quads : PolyMesh, closed all-quad mesh; topo : its Topology.
    crease : (n_edges,) bool crease edges.
    special : (n_vertices,) bool, the vertices whose limit departs from a regular one (an
        extraordinary vertex, a dart, a corner, a crease vertex with a sector other than
        two faces); ``gamma`` is exactly 1 at the others.

    Returns
    -------
    (n_vertices,) float64, clipped to :data:`GROWTH_RANGE`.
    """
    fv = quads.face_vertices
    spoke, valence, _ = spoke_order(quads, topo)
    bits = np.zeros(len(quads.vertices), dtype=np.int64)
    on = np.flatnonzero(crease[topo.corner_edge])
    np.add.at(bits, fv[on], np.left_shift(1, spoke[on]))
    gamma = np.ones(len(quads.vertices))
    at = np.flatnonzero(special)
    kinds, kind = np.unique(np.stack([valence[at], bits[at]], axis=1), axis=0,
                            return_inverse=True)
    for index, (n, b) in enumerate(kinds.tolist()):
        magnitude = np.abs(np.linalg.eigvals(template_matrix(n, crease_spokes=b)))
        below = magnitude[magnitude < 1.0 - 1e-9]
        gamma[at[kind.reshape(-1) == index]] = -np.log2(below.max())
    return np.clip(gamma, *GROWTH_RANGE)


def warped_params(u, v, growth):
    """The limit's parameters at which the patches' points ``(u, v)`` are matched.

    Parameters
    ----------
    u, v : (f, p) float64 patch parameters, ``p`` per quad.
    growth : (f, 4) float64 exponents of :func:`vertex_growth` at each quad's corners.

    Returns
    -------
    (u', v') : two (f, p) float64 arrays; within :data:`WARP_RADIUS` of corner ``k`` the point
    moves along its direction from the corner to distance ``R (r / R) ** (1 / gamma)``;
    elsewhere (and where ``gamma`` is 1) unchanged.
    """
    u, v = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
    for k in range(4):
        g = growth[:, k:k + 1]
        if np.all(g == 1.0):
            continue
        c = CORNER_UV[k]
        du, dv = u - c[0], v - c[1]
        r = np.hypot(du, dv)
        inside = (r > 0.0) & (r < WARP_RADIUS) & (g != 1.0)
        scale = np.ones_like(r)
        expo = np.broadcast_to(1.0 / g - 1.0, r.shape)
        scale[inside] = (r[inside] / WARP_RADIUS) ** expo[inside]
        u, v = c[0] + du * scale, c[1] + dv * scale
    return u, v

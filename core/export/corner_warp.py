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

``gamma`` comes from the eigen-decomposition of the local subdivision matrix of each special
vertex's kind, one value per spoke (:func:`spoke_growth`: a crease spoke follows its crease
curve, whose modes are not those of the faces between the creases), blended between a
corner's two spokes inside the patch; the two patches of an edge are fitted to the same limit
points along it, and the fit stays a fixed linear map of the cage. The disks
of radius :data:`WARP_RADIUS` around the four corners do not overlap, and the warp is the
identity on a disk's rim and at its corner, so patch corners and the middle of every side
keep their exact limit points.
"""
import numpy as np

from core.export.brep_topology import CORNER_UV
from core.subdivision.limit import TEMPLATE_RADIUS, template_id, spoke_order, template_matrix

WARP_RADIUS = 0.5
"""Parameter distance from a corner within which the targets are warped (half a side: the
four corners' disks touch but do not overlap)."""
GROWTH_RANGE = (0.5, 2.0)
"""Exponents are clipped to this range (a guard: Catmull-Clark's smooth vertices have exponents
from about 1.29 at valence 3 down towards 0.61 for large valences)."""


def _kind_growth(n, bits):
    """(n,) exponents along the spokes of a vertex of valence ``n`` with crease spokes
    ``bits``: ``-log2`` of the largest eigenvalue magnitude below 1 of its local subdivision
    matrix (:func:`core.subdivision.limit.template_matrix`) among the eigenvectors that move
    the spoke's template points (a crease spoke follows only the crease curve's modes)."""
    w, vectors = np.linalg.eig(template_matrix(n, crease_spokes=bits))
    magnitude = np.abs(w)
    moving = magnitude < 1.0 - 1e-9
    r = TEMPLATE_RADIUS
    growth = np.ones(n)
    for s in range(n):
        ids = template_id(n, np.full(r, s), np.arange(1, r + 1), np.zeros(r, dtype=np.int64))
        entry = np.abs(vectors[ids]).max(axis=0)
        used = moving & (entry > 1e-9 * np.abs(vectors).max(axis=0))
        growth[s] = -np.log2(magnitude[used].max())
    return growth


def spoke_growth(quads, topo, crease, special):
    """Growth exponents ``gamma = -log2(lambda)`` of the limit surface along every spoke.

    ``lambda`` is the rate at which the spoke's points contract towards the vertex's limit
    point under subdivision: the largest eigenvalue magnitude below 1 of the local
    subdivision matrix of the vertex's kind (valence and crease spokes) whose eigenvector
    moves that spoke (:func:`_kind_growth`); the limit's distance from the vertex then grows
    like ``r ** gamma`` in the parameter distance ``r`` along it. At a vertex with crease
    edges an exponent above 1 is taken as 1: its crease curves grow linearly, and a spoke
    between them that only faster-contracting modes move is left unwarped. A function of the
    topology only, so the fit stays linear in the cage.

    Parameters
    ----------
    quads : PolyMesh, closed all-quad mesh; topo : its Topology.
    crease : (n_edges,) bool crease edges.
    special : (n_vertices,) bool, the vertices whose limit departs from a regular one (an
        extraordinary vertex, a dart, a corner, a crease vertex with a sector other than
        two faces); ``gamma`` is exactly 1 on the spokes of the others.

    Returns
    -------
    (k,) float64 per corner: along the half-edge leaving it, clipped to :data:`GROWTH_RANGE`.
    """
    fv = quads.face_vertices
    spoke, valence, _ = spoke_order(quads, topo)
    bits = np.zeros(len(quads.vertices), dtype=np.int64)
    on = np.flatnonzero(crease[topo.corner_edge])
    np.add.at(bits, fv[on], np.left_shift(1, spoke[on]))
    gamma = np.ones(len(fv))
    at = np.flatnonzero(special[fv])
    kinds, kind = np.unique(np.stack([valence[fv[at]], bits[fv[at]]], axis=1), axis=0,
                            return_inverse=True)
    for index, (n, b) in enumerate(kinds.tolist()):
        mine = at[kind.reshape(-1) == index]
        growth = _kind_growth(n, b)
        gamma[mine] = (np.minimum(growth, 1.0) if b else growth)[spoke[mine]]
    return np.clip(gamma, *GROWTH_RANGE)


def corner_growth(topo, gamma):
    """(m, 4, 2) exponents at each quad's corners (:func:`warped_params`): ``[:, k, 0]``
    along side ``k`` from corner ``k``, ``[:, k, 1]`` along side ``k - 1`` towards corner
    ``k + 3``, from the per-corner spoke exponents ``gamma`` (k,) of :func:`spoke_growth`."""
    corner = np.arange(len(gamma))
    back = topo.twin[topo.prev_corner[corner]]
    return np.stack([gamma, gamma[back]], axis=1).reshape(-1, 4, 2)


def warped_params(u, v, growth):
    """The limit's parameters at which the patches' points ``(u, v)`` are matched.

    Parameters
    ----------
    u, v : (f, p) float64 patch parameters, ``p`` per quad.
    growth : (f, 4, 2) float64 exponents of :func:`corner_growth`.

    Returns
    -------
    (u', v') : two (f, p) float64 arrays; within :data:`WARP_RADIUS` of corner ``k`` the point
    moves along its direction from the corner to distance ``R (r / R) ** (1 / gamma)``, with
    ``gamma`` blended linearly in the angle between the corner's two sides (their spokes'
    exponents); elsewhere (and where ``gamma`` is 1) unchanged.
    """
    u, v = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
    for k in range(4):
        g = growth[:, k]
        if np.all(g == 1.0):
            continue
        c = CORNER_UV[k]
        along = CORNER_UV[(k + 1) % 4] - c
        du, dv = u - c[0], v - c[1]
        a = du * along[0] + dv * along[1]
        r = np.hypot(du, dv)
        w = np.arccos(np.clip(a / np.maximum(r, 1e-300), -1.0, 1.0)) / (0.5 * np.pi)
        gamma = (1.0 - w) * g[:, :1] + w * g[:, 1:]
        inside = (r > 0.0) & (r < WARP_RADIUS) & (gamma != 1.0)
        scale = np.ones_like(r)
        scale[inside] = (r[inside] / WARP_RADIUS) ** (1.0 / gamma[inside] - 1.0)
        u, v = c[0] + du * scale, c[1] + dv * scale
    return u, v

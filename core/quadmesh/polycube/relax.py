# SPDX-License-Identifier: LGPL-2.1-or-later
"""Even out the embedded base mesh on the target (the last step of the embedding).

The Tutte map places lattice points where a chart's integer polygon says, which is uneven where
the polygon's proportions differ from the chart's (a tapered flange is a rectangle in the
polycube). A few rounds of Laplacian smoothing constrained to the target fix that: every point
moves to the mean of its quad-mesh neighbours and is projected back, an interior point onto its
own chart's triangles, a side point onto its side's vertex chain (so both charts of the side
still share it), while corners stay on their target vertices. Projection onto the point's own
chart or side, never onto the nearest surface, keeps points on their sheet across thin members.
"""
import numpy as np

from core.mesh_topology import neighbour_mean
from core.target_surface import TargetSurface
from core.quadmesh.polycube.embed import arc_fractions, point_on_chain

RELAX_ROUNDS = 8
"""Rounds of constrained smoothing."""
MIN_GAP = 0.1
"""Side points stay at least this many units apart along their side."""


def _slide_along(points, chain, order, length):
    """Closest points on the polyline ``chain`` (k, 3) to the side points ``points`` (q, 3).

    ``order`` (q,) is each point's rank along the side and ``length`` the side's length in
    units; the points keep that order, at least a tenth of a unit apart and from the ends.
    """
    a, b = chain[:-1], chain[1:]
    d = b - a
    t = np.einsum("qsk,sk->qs", points[:, None] - a[None], d) / np.maximum(
        np.einsum("sk,sk->s", d, d), 1e-300)
    t = np.clip(t, 0.0, 1.0)
    foot = a[None] + t[..., None] * d[None]
    best = np.argmin(np.linalg.norm(foot - points[:, None], axis=2), axis=1)
    fractions = arc_fractions(chain)
    rows = np.arange(len(points))
    along = fractions[best] + t[rows, best] * (fractions[best + 1] - fractions[best])
    gap = MIN_GAP / float(length)
    ranked = np.sort(along)
    # keep the order and the gaps: ranked[i] >= ranked[i-1] + gap, and inside (gap, 1 - gap)
    floor = gap * (1 + np.arange(len(points)))
    ceiling = 1.0 - gap * (len(points) - np.arange(len(points)))
    ranked = np.maximum.accumulate(np.maximum(ranked - floor, 0.0)) + floor
    ranked = np.minimum(ranked, ceiling)
    return point_on_chain(chain, fractions, ranked[np.argsort(np.argsort(order))])


def relax_on_target(mesh, V, F, face_chart, vertex_side, vertex_step, side_length,
                    vertex_chart, side_chains, rounds=RELAX_ROUNDS):
    """Constrained Laplacian smoothing of a base mesh whose vertices lie on the target.

    Parameters
    ----------
    mesh : PolyMesh, closed quad mesh on the target.
    V : (n, 3) float64, F : (m, 3) int64 the target; face_chart : (m,) int64 chart per face.
    vertex_side : (p,) int64 side each base vertex lies on (-1 where none).
    vertex_step : (p,) float64 its arc-length fraction along that side at the start (side
        points slide along their side but keep this order, so they never meet).
    side_length : (s,) int64 length of every side in units.
    vertex_chart : (p,) int64 chart each interior base vertex lies in (-1 where none).
        Vertices with neither (the corners) stay where they are.
    side_chains : callable ``side -> (k, 3) float64`` the side's target vertex chain.
    rounds : int, smoothing rounds.

    Returns
    -------
    (p, 3) float64 new positions, on the target.
    """
    positions = np.array(mesh.vertices, dtype=np.float64)
    charts = np.unique(vertex_chart[vertex_chart >= 0])
    surfaces = {}
    for chart in charts.tolist():
        faces = F[face_chart == chart]
        used, local = np.unique(faces, return_inverse=True)
        surfaces[chart] = TargetSurface(V[used], local.reshape(-1, 3))
    sides = np.unique(vertex_side[vertex_side >= 0])
    chains = {side: side_chains(side) for side in sides.tolist()}
    for _ in range(rounds):
        moved = neighbour_mean(positions, mesh.face_vertices, mesh.face_offsets)
        for chart, surface in surfaces.items():
            rows = np.flatnonzero(vertex_chart == chart)
            positions[rows] = surface.nearest(moved[rows]).point
        for side, chain in chains.items():
            rows = np.flatnonzero(vertex_side == side)
            positions[rows] = _slide_along(moved[rows], chain, vertex_step[rows],
                                           side_length[side])
    return positions

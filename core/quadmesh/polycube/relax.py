# SPDX-License-Identifier: LGPL-2.1-or-later
"""Even out the embedded base mesh on the target, and untangle its folds (the last steps of
the embedding).

The Tutte map places lattice points where a chart's integer polygon says, which is uneven where
the polygon's proportions differ from the chart's (a tapered flange is a rectangle in the
polycube). A few rounds of Laplacian smoothing constrained to the target fix that: every point
moves to the mean of its quad-mesh neighbours and is projected back, an interior point onto its
own chart's triangles, a side point onto its side's vertex chain (so both charts of the side
still share it), while corners stay on their target vertices. Projection onto the point's own
chart or side, never onto the nearest surface, keeps points on their sheet across thin members.

Where a polygon differs much from its chart, a unit square covers a long, bent strip of the
chart and the chord quad of its corners folds over, though the Tutte map does not. The
untangled copy (:func:`untangle_on_target`) moves the same points under the same constraints
to minimise a foldover-free energy (Garanzha, Kaporin, Kudryavtseva, Protais, Ray, Sokolov,
"Foldover-free maps in 50 lines of code", 2021) of every quad corner in the quad's tangent
plane, plus the same energy of the determinant of the Catmull-Clark limit normal at each
quad's centre against the quad's normal, so the faces' limit normals face out as well.
"""
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from core.mesh_topology import neighbour_mean
from core.target_surface import TargetSurface
from core.quadmesh.orientation import face_centre_operators
from core.quadmesh.polycube.embed import arc_fractions, point_on_chain

RELAX_ROUNDS = 8
"""Rounds of constrained smoothing."""
MIN_GAP = 0.1
"""Side points stay at least this many units apart along their side."""
UNTANGLE_ROUNDS = 8
"""Rounds of :func:`untangle_on_target` (each on the tangent planes of the last)."""
UNTANGLE_ITERATIONS = 40
"""L-BFGS iterations per round."""
AREA_WEIGHT = 1.0 / 128.0
"""Weight of the area term of :func:`untangling_energy` (against the shape term)."""
EPS_START, EPS_FACTOR = 1.0, 0.3
"""``eps`` of the first round of :func:`untangle_on_target` and its factor per round."""
FLAW_RINGS = 2
"""The untangling near the flaws moves the vertices within this many rings of them."""
LIMIT_WEIGHT = 1.0
"""Weight of the limit normals' term of :func:`untangle_on_target` (against the corners')."""
STEP = 0.5
"""Each round moves a vertex at most this fraction of its mean edge length along each of
its directions (the moves are made in tangent planes, then put back on the target)."""


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


@dataclass(frozen=True)
class RelaxedLayout:
    """Vertex positions of an embedded layout after :func:`relax_on_target`.

    smoothed : (p, 3) float64 after the Laplacian rounds.
    untangle : callable ``(rings) -> (p, 3) float64`` those with folded corners and limit
        normals untangled (:func:`untangle_on_target`, all vertices moving where ``rings`` is
        None, else those near the flaws), computed when called (only flawed layouts need
        it).
    """

    smoothed: np.ndarray
    untangle: Callable[[object], np.ndarray]


class _OnTarget:
    """Where each base vertex may move: an interior point on its own chart's triangles, a side
    point along its side's vertex chain (in its order, :func:`_slide_along`), a corner nowhere.

    Parameters as :func:`relax_on_target`.
    """

    def __init__(self, V, F, face_chart, vertex_side, vertex_step, side_length, vertex_chart,
                 side_chains, quad_chart):
        self.chart_surfaces = {}
        for chart in np.unique(np.concatenate([vertex_chart[vertex_chart >= 0],
                                               quad_chart])).tolist():
            faces = F[face_chart == chart]
            used, local = np.unique(faces, return_inverse=True)
            self.chart_surfaces[chart] = TargetSurface(V[used], local.reshape(-1, 3))
        self.chart_rows = {chart: np.flatnonzero(vertex_chart == chart)
                           for chart in np.unique(vertex_chart[vertex_chart >= 0]).tolist()}
        self.surfaces = {chart: self.chart_surfaces[chart] for chart in self.chart_rows}
        self.quad_chart = quad_chart
        self.side_rows = {side: np.flatnonzero(vertex_side == side)
                          for side in np.unique(vertex_side[vertex_side >= 0]).tolist()}
        self.chains = {side: side_chains(side) for side in self.side_rows}
        self.vertex_step, self.side_length = vertex_step, side_length

    def normals(self, positions, quads):
        """(f, 3) float64 unit normal of every quad: the normals of its chart's triangles
        nearest its corners, summed."""
        total = np.zeros((len(quads), 3))
        for chart, surface in self.chart_surfaces.items():
            rows = np.flatnonzero(self.quad_chart == chart)
            corners = positions[quads[rows]].reshape(-1, 3)
            normal = surface.face_normals[surface.nearest(corners).face]
            total[rows] = normal.reshape(-1, 4, 3).sum(axis=1)
        return total / np.maximum(np.linalg.norm(total, axis=1, keepdims=True), 1e-300)

    def project(self, positions, moved):
        """(p, 3) float64 ``moved`` put back on the target (``positions`` where fixed)."""
        out = np.array(positions, dtype=np.float64)
        for chart, surface in self.surfaces.items():
            rows = self.chart_rows[chart]
            out[rows] = surface.nearest(moved[rows]).point
        for side, chain in self.chains.items():
            rows = self.side_rows[side]
            out[rows] = _slide_along(moved[rows], chain, self.vertex_step[rows],
                                     self.side_length[side])
        return out

    def directions(self, positions):
        """(p, 2, 3) float64 unit directions each vertex may move in at ``positions``: two
        tangents of its chart, its side's tangent and zero, or zeros (a corner)."""
        out = np.zeros((len(positions), 2, 3))
        for chart, surface in self.surfaces.items():
            rows = self.chart_rows[chart]
            near = surface.nearest(positions[rows])
            normal = surface.face_normals[near.face]
            first = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal), axis=1)])
            first /= np.maximum(np.linalg.norm(first, axis=1, keepdims=True), 1e-300)
            out[rows, 0] = first
            out[rows, 1] = np.cross(normal, first)
        for side, chain in self.chains.items():
            rows = self.side_rows[side]
            d = chain[1:] - chain[:-1]
            t = np.einsum("qsk,sk->qs", positions[rows][:, None] - chain[:-1][None], d) / (
                np.maximum(np.einsum("sk,sk->s", d, d), 1e-300))
            foot = chain[:-1][None] + np.clip(t, 0.0, 1.0)[..., None] * d[None]
            best = np.argmin(np.linalg.norm(foot - positions[rows][:, None], axis=2), axis=1)
            tangent = d[best]
            out[rows, 0] = tangent / np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True),
                                                1e-300)
        return out


def relax_on_target(mesh, V, F, face_chart, vertex_side, vertex_step, side_length,
                    vertex_chart, side_chains, quad_chart, rounds=RELAX_ROUNDS):
    """Constrained Laplacian smoothing of a base mesh whose vertices lie on the target, and
    the untangling of the smoothed mesh's folds (:func:`untangle_on_target`), deferred.

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
    quad_chart : (f,) int64 chart of every quad; a chart's quads are untangled against
        squares of its area shared out equally.
    rounds : int, smoothing rounds.

    Returns
    -------
    RelaxedLayout, both (p, 3) float64 positions on the target.
    """
    positions = np.array(mesh.vertices, dtype=np.float64)
    where = _OnTarget(V, F, face_chart, vertex_side, vertex_step, side_length, vertex_chart,
                      side_chains, quad_chart)
    for _ in range(rounds):
        moved = neighbour_mean(positions, mesh.face_vertices, mesh.face_offsets)
        positions = where.project(positions, moved)
    area = np.bincount(face_chart, weights=_triangle_areas(V, F))
    count = np.bincount(quad_chart, minlength=len(area))
    size = np.sqrt(area[quad_chart] / count[quad_chart])
    return RelaxedLayout(positions, lambda rings: untangle_on_target(positions, mesh, size,
                                                                     where, rings))


def _mean_edge(positions, quads):
    """(p,) float64 mean length of the quad edges at each vertex."""
    ahead = np.roll(quads, -1, axis=1)
    length = np.linalg.norm(positions[ahead] - positions[quads], axis=2)
    total = np.bincount(quads.reshape(-1), weights=length.reshape(-1), minlength=len(positions))
    total += np.bincount(ahead.reshape(-1), weights=length.reshape(-1), minlength=len(positions))
    count = 2.0 * np.bincount(quads.reshape(-1), minlength=len(positions))
    return total / np.maximum(count, 1.0)


def _triangle_areas(V, F):
    """(m,) float64 area of every triangle."""
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                axis=1)


def _chi(det, eps):
    """The regularised determinant of Garanzha et al. and its derivative in ``det``:
    ``(det + sqrt(eps^2 + det^2)) / 2``, positive for every ``det`` (written without the
    cancellation where ``det`` is negative)."""
    root = np.sqrt(eps * eps + det * det)
    positive = det > 0
    chi = np.where(positive, 0.5 * (det + root),
                   0.5 * eps * eps / np.where(positive, 1.0, root - det))
    return chi, 0.5 * (1.0 + det / root)


def corner_jacobians(points, quads, frames, size):
    """Jacobians of the corners of quads seen in their tangent frames, against a unit square.

    Parameters
    ----------
    points : (p, 3) float64 vertex positions.
    quads : (f, 4) int64 corners, counter-clockwise seen from outside.
    frames : (f, 2, 3) float64 two orthonormal tangent directions of each quad (their cross
        product points outside).
    size : (f,) float64 edge length of the reference square of each quad.

    Returns
    -------
    (f, 4, 2, 2) float64: column 0 the edge to the next corner, column 1 the edge to the
    previous one, in the frame and divided by ``size``; a corner is folded where the
    determinant is not positive.
    """
    here = points[quads]
    across = frames[:, None]  # (f, 1, 2, 3)
    # each product summed over k in order, written out (einsum is several times slower here)
    columns = [_along(across, (here[:, step] - here)[:, :, None]) for step in (_AHEAD, _BEHIND)]
    return np.stack(columns, axis=-1) / size[:, None, None, None]


_AHEAD, _BEHIND = [1, 2, 3, 0], [3, 0, 1, 2]
"""Each quad corner's next and previous corners."""


def _along(frames, vectors):
    """``sum_k frames[..., k] * vectors[..., k]`` over the last axis (3), broadcast."""
    return (frames[..., 0] * vectors[..., 0] + frames[..., 1] * vectors[..., 1]
            + frames[..., 2] * vectors[..., 2])


def untangling_energy(jacobians, eps, area_weight=AREA_WEIGHT):
    """Foldover-free energy of corner Jacobians and its derivative (Garanzha et al. 2021).

    ``f(J) = ((1 - w) |J|^2 + w (det J^2 + 1)) / chi(det J, eps)``: the first term is the
    shape distortion (least for a square), the second the area change (least for the
    reference size); ``chi`` (:func:`_chi`) makes the energy finite for folded corners,
    and as ``eps`` goes to zero it becomes a barrier against folding.

    Parameters
    ----------
    jacobians : (..., 2, 2) float64; eps : float > 0; area_weight : float ``w`` in [0, 1].

    Returns
    -------
    energy : float, the sum over the corners.
    gradient : (..., 2, 2) float64 its derivative in every Jacobian.
    """
    a, b = jacobians[..., 0, 0], jacobians[..., 0, 1]
    c, d = jacobians[..., 1, 0], jacobians[..., 1, 1]
    det = a * d - b * c
    chi, chi_prime = _chi(det, eps)
    frobenius = np.einsum("...ij,...ij->...", jacobians, jacobians)
    numerator = (1.0 - area_weight) * frobenius + area_weight * (det * det + 1.0)
    cofactor = np.stack([np.stack([d, -c], axis=-1), np.stack([-b, a], axis=-1)], axis=-2)
    along_det = (2.0 * area_weight * det - numerator * chi_prime / chi) / chi
    gradient = (2.0 * (1.0 - area_weight) / chi)[..., None, None] * jacobians \
        + along_det[..., None, None] * cofactor
    return float((numerator / chi).sum()), gradient


def quad_frames(normals):
    """(f, 2, 3) float64 orthonormal tangent pairs whose cross product is each unit normal
    of ``normals`` (f, 3)."""
    helper = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    first = np.cross(normals, helper)
    first /= np.maximum(np.linalg.norm(first, axis=1, keepdims=True), 1e-300)
    return np.stack([first, np.cross(normals, first)], axis=1)


def folded_corners(points, quads, frames):
    """(f, 4) bool quad corners that are not counter-clockwise in their quad's frame."""
    jac = corner_jacobians(points, quads, frames, np.ones(len(quads)))
    return jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0] <= 0.0


def untangle_on_target(positions, mesh, quad_size, where, rings=None, rounds=UNTANGLE_ROUNDS,
                       iterations=UNTANGLE_ITERATIONS):
    """Folded quad corners and limit normals of a cage untangled on the target.

    Each round fixes every quad's tangent frame (from the target's normals at its corners)
    and every vertex's directions of motion (:meth:`_OnTarget.directions`), minimises
    :func:`untangling_energy` of all quad corners plus that of the determinants of the limit
    normals at the face centres against the quads' normals (in units of a typical quad's)
    over the moves along those directions (L-BFGS, each move at most :data:`STEP` of the
    vertex's mean edge), puts the moved vertices back on the target
    (:meth:`_OnTarget.project`) and divides ``eps`` by a constant factor, so the energy goes
    from smooth to a barrier against folding (Garanzha et al., "Foldover-free maps in 50 lines
    of code", 2021, lower ``eps`` by the smallest determinant instead; one fold that cannot be
    undone would keep it large here).

    Parameters
    ----------
    positions : (p, 3) float64 vertex positions on the target.
    mesh : PolyMesh, the closed all-quad cage (its faces counter-clockwise seen from outside;
        its vertices are not read).
    quad_size : (f,) float64 edge length of each quad's reference square.
    where : _OnTarget.
    rings : int or None, move only the vertices within this many rings of the quads flawed
        at the start (a folded corner or a limit normal facing away, :func:`_near_flaws`),
        the rest staying where they are; None: every vertex.
    rounds, iterations : int, rounds and L-BFGS iterations per round.

    Returns
    -------
    (p, 3) float64 the positions, after any round, with the fewest limit normals facing away
    from their quads, then folded corners (``positions`` itself where none had fewer).
    """
    quads = mesh.face_vertices.reshape(-1, 4)
    _, tangent_u, tangent_v = face_centre_operators(mesh)
    movable = np.ones(len(positions), dtype=bool) if rings is None else _near_flaws(
        positions, quads, quad_frames(where.normals(positions, quads)), tangent_u, tangent_v,
        rings)
    best, best_folded = positions, None
    eps = None
    # every quad corner's gradient goes to the corner after it, the one before it and itself
    gather = np.concatenate([np.roll(quads, -1, axis=1), np.roll(quads, 1, axis=1),
                             quads]).reshape(-1)
    to_vertices_u, to_vertices_v = tangent_u.T, tangent_v.T
    for _ in range(rounds):
        frames = quad_frames(where.normals(positions, quads))
        normal = np.cross(frames[:, 0], frames[:, 1])
        folded = _flaws(positions, quads, frames, tangent_u, tangent_v)
        # the limit normals' determinants against the quads' normals, in units of the
        # typical one of a quad of the reference size
        limit_det = _centre_determinants(positions, frames, tangent_u, tangent_v)
        unit = np.median(limit_det[limit_det > 0] / quad_size[limit_det > 0] ** 2) \
            if (limit_det > 0).any() else 1.0
        limit_scale = unit * quad_size ** 2
        if best_folded is None or folded < best_folded:
            best, best_folded = positions, folded
        directions = where.directions(positions) * movable[:, None, None]
        eps = EPS_START if eps is None else eps * EPS_FACTOR

        def energy(x, eps=eps, frames=frames, directions=directions):
            moved = positions + np.einsum("pdk,pd->pk", directions, x.reshape(-1, 2))
            value, grad_j = untangling_energy(corner_jacobians(moved, quads, frames, quad_size),
                                              eps)
            # J = frame^T (edge) / size: back to the edges, then to the corners
            grad_e = (frames[:, None, 0, :, None] * grad_j[:, :, 0, None, :]
                      + frames[:, None, 1, :, None] * grad_j[:, :, 1, None, :]) \
                / quad_size[:, None, None, None]
            grad = _sum_at(len(positions), gather,
                           np.concatenate([grad_e[..., 0], grad_e[..., 1],
                                           -grad_e.sum(axis=-1)]).reshape(-1, 3))
            # the limit normal at each face centre against the quad's normal
            tu, tv = tangent_u @ moved, tangent_v @ moved
            det = np.einsum("fk,fk->f", normal, _cross(tu, tv)) / limit_scale
            chi, chi_prime = _chi(det, eps)
            value += LIMIT_WEIGHT * float(((det * det + 1.0) / chi).sum())
            along = LIMIT_WEIGHT * (2.0 * det - (det * det + 1.0) * chi_prime / chi) / chi \
                / limit_scale
            grad += to_vertices_u @ (along[:, None] * _cross(tv, normal))
            grad += to_vertices_v @ (along[:, None] * _cross(normal, tu))
            return value, np.einsum("pdk,pk->pd", directions, grad).reshape(-1)

        reach = np.repeat(STEP * _mean_edge(positions, quads), 2)
        found = minimize(energy, np.zeros(2 * len(positions)), jac=True, method="L-BFGS-B",
                         bounds=list(zip(-reach, reach)), options={"maxiter": iterations})
        moved = positions + np.einsum("pdk,pd->pk", directions, found.x.reshape(-1, 2))
        positions = where.project(positions, moved)
    frames = quad_frames(where.normals(positions, quads))
    if best_folded is None or _flaws(positions, quads, frames, tangent_u, tangent_v) < best_folded:
        best = positions
    return best


def _cross(a, b):
    """Row-wise cross products of (k, 3) float64 ``a`` and ``b``: ``np.cross``'s products and
    differences, without its per-call overhead (the energy takes three per evaluation)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _sum_at(n, index, values):
    """(n, 3) float64 sums of the rows of ``values`` ((k, 3) float64) at ``index`` ((k,)
    int64), each added in the order given (as ``np.add.at`` into zeros, column by column)."""
    return np.stack([np.bincount(index, weights=values[:, axis], minlength=n)
                     for axis in range(3)], axis=1)


def _centre_determinants(positions, frames, tangent_u, tangent_v):
    """(f,) float64 determinants of the limit tangents at each face centre against the quad's
    normal (the cross product of its two ``frames`` axes, (f, 2, 3) float64): negative where the limit normal
    is more than 90 degrees from the quad's. ``tangent_u``, ``tangent_v``: (f, p) sparse
    centre-derivative operators (:func:`core.quadmesh.orientation.face_centre_operators`)."""
    normal = np.cross(frames[:, 0], frames[:, 1])
    return np.einsum("fk,fk->f", normal, np.cross(tangent_u @ positions, tangent_v @ positions))


def _near_flaws(positions, quads, frames, tangent_u, tangent_v, rings):
    """(p,) bool vertices within ``rings`` (>= 1) rings of quads with a folded corner or a
    limit normal facing away from the quad's normal."""
    det = _centre_determinants(positions, frames, tangent_u, tangent_v)
    flawed = (det < 0) | folded_corners(positions, quads, frames).any(axis=1)
    near = np.zeros(len(positions), dtype=bool)
    near[quads[flawed].reshape(-1)] = True
    for _ in range(rings - 1):
        near[quads[near[quads].any(axis=1)].reshape(-1)] = True
    return near


def _flaws(positions, quads, frames, tangent_u, tangent_v):
    """``(faces, corners)``: quads whose limit normal at the centre is more than 90 degrees
    from their normal, and folded quad corners (compared as a pair, the first first)."""
    det = _centre_determinants(positions, frames, tangent_u, tangent_v)
    return int((det < 0).sum()), int(folded_corners(positions, quads, frames).sum())

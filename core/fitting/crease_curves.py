# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit the cage's crease curves to the target's feature lines.

A crease of the cage is the uniform cubic B-spline curve of its crease polygon
(:mod:`core.subdivision.catmull_clark`), so a crease polygon whose vertices lie on the
target's feature line, as the feature-preserving decimation leaves them
(:mod:`core.quadmesh.decimation.feature_decimation`), gives a curve that cuts inside every turn: a
hole's rim of five crease vertices on a circle of radius ``r`` has a limit curve of radius
about ``0.77 r``, and the material of the limit solid reaches into the hole. On a machined
part with many such holes the cage's limit solid leaves a clear share of the target's
volume outside it, and the least-squares fit cannot take it out: moving a rim outwards
folds the few wide faces round it, and the fit's crossing hold-back puts the rim back.

:func:`fit_crease_curves` moves only the line crease vertices (two crease edges; corners
stay, their limit is the vertex itself), for the crease curves alone: each crease edge of
the cage is the image of a chain of the target's feature edges between the target
vertices its two ends sit on (the decimation keeps each feature vertex a target vertex,
and its corners as corners), found as the shortest path in the target's feature network
that passes no other crease vertex. The limit points of the crease edge's fine vertices
should lie on that chain: a few Gauss-Newton rounds of point-to-line least squares (the
residual across the chain at its closest point), with a weak pull of each point to the
chain's point at the same arc-length fraction (so the points do not bunch up where the
line leaves them free) and a small pull towards the cage (vertices without a chain stay).
A point-to-point fit at the arc-length fractions alone bends the curve far off next to a
kink between a long and a short edge, and raises the fit's largest distance. A vertex moves at most
``CREASE.max_move`` times its shortest crease edge, and the move is then held back where the
limit surface would cross itself (:func:`core.fitting.crossings.hold_back_crossings`).

The inside fit that starts from it leaves much less of the target's volume outside and comes
closer on average (``benchmarks/FIT_RESULTS.md``). What can stay outside is where moving a rim
out would fold wide fan quads round it (held back; the base mesh does not make those quads,
:func:`core.quadmesh.decimation.paired_decimation._rim_folds`) and where the crease polygons are too
coarse for their outlines (a rounded octagon of a few crease vertices keeps some of its
crease curve off the feature lines).
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from core.fitting.crossings import hold_back_crossings
from core.geometry import shortest_edges_at
from core.quadmesh.creases import CREASE_ANGLE, closed_network, feature_edges
from core.tolerances import CONTACT


@dataclass(frozen=True)
class CreaseCurveSettings:
    """Tuned constants of :func:`fit_crease_curves`."""

    damping: float = 1e-3
    """Weight of ``|V - V_cage|^2`` per crease vertex against the unit-weight limit-point
    rows."""
    along_weight: float = 0.1
    """Weight of a limit point's pull to its arc-length point against its pull onto the
    line."""
    rounds: int = 4
    """Gauss-Newton rounds (closest points on the lines found again each round)."""
    max_move: float = 1.0
    """Farthest a crease vertex moves, times its shortest crease edge. A five-vertex hole rim
    moves out by about a quarter of its edges; a vertex at a kink between a long and a short
    straight edge can otherwise be carried out by many times its short edge, the curve still
    on the lines but the faces round it dragged off the target."""
    path_reach: float = 4.0
    """A crease edge's feature chain is searched up to this many times the edge's length
    (a chain between two rim vertices of a five-vertex hole is 1.07 times the chord)."""


CREASE = CreaseCurveSettings()
"""The settings this module runs with."""




@dataclass
class CreaseFit:
    """Outcome of :func:`fit_crease_curves`.

    vertices : (n, 3) float64 base vertices, the crease vertices moved.
    matched : int, crease edges whose feature chain was found on the target.
    creases : int, crease edges of the cage.
    held : int, base vertices whose move was cut back where it crossed.
    """

    vertices: np.ndarray
    matched: int
    creases: int
    held: int


def fit_crease_curves(base, fine, limit_map, triangles, target_vertices, target_faces):
    """Crease vertices of ``base`` moved so its crease curves follow the target's features.

    Parameters
    ----------
    base : PolyMesh, the cage (model units); without creases nothing moves.
    fine : PolyMesh, its level-``levels`` refinement (``build_hierarchy(base, levels)``),
        whose vertex numbering starts with the base vertices and whose creases are the
        halves of the base creases.
    limit_map : (n_fine, n) sparse CSR, the fine vertices' limit points ``limit_map @ V``.
    triangles : (t, 3) int64 fine triangles (for the crossing hold-back).
    target_vertices : (m, 3) float64; target_faces : (f, 3) int64, closed, outward.

    Returns
    -------
    CreaseFit; its limit surface has no crossing pair that the cage's does not have.
    """
    V0 = np.asarray(base.vertices, dtype=np.float64)
    n = len(V0)
    if not base.n_creases:
        return CreaseFit(V0, 0, 0, 0)
    creases = np.sort(np.asarray(base.creases, dtype=np.int64), axis=1)
    count = np.bincount(creases.reshape(-1), minlength=n)
    free = np.flatnonzero(count == 2)
    on_target = _target_vertex_of(V0, target_vertices)
    graph = _FeatureGraph(target_vertices, target_faces)
    ends = set(on_target[np.unique(creases)].tolist()) - {-1}
    rows, along, chains, polylines = [], [], [], []
    fine_chains = _fine_chains(fine, n, creases)
    ends_of = np.array(list(fine_chains), dtype=np.int64).reshape(-1, 2)
    for ((a, b), inner), path in zip(fine_chains.items(),
                                     graph.paths(on_target[ends_of], ends)):
        if path is None:
            continue
        steps = len(inner) + 1
        rows.extend([a, *inner, b])
        polylines.append(target_vertices[path])
        along.append(_along(polylines[-1], np.arange(steps + 1) / steps))
        chains.append(np.full(steps + 1, len(chains)))
    if not rows or not len(free):
        return CreaseFit(V0, len(chains), len(creases), 0)
    moved = _fitted(limit_map, np.asarray(rows), np.concatenate(along),
                    np.concatenate(chains), _Polylines(polylines), V0, free,
                    CREASE.max_move * shortest_edges_at(V0, creases)[free])
    vertices, held, _ = hold_back_crossings(V0, moved, limit_map, triangles, clean=False)
    return CreaseFit(vertices, len(chains), len(creases), held)


def _fitted(limit_map, rows, along, chain, curves, V0, free, reach):
    """Gauss-Newton rounds of the crease-curve fit; the ``free`` vertices move.

    Each limit point ``limit_map[rows] @ V`` ((r,) fine vertices) is pulled onto its chain's
    feature polyline (point-to-line: the residual's part across the line at its closest
    point, weight 1) and, weakly (``CREASE.along_weight``), to the point at its arc-length
    fraction (``along``, (r, 3)), which keeps the parametrisation even; ``CREASE.damping``
    pulls towards the cage. A vertex moves at most ``reach`` ((f,) model units) from the
    cage each round (the move is shortened, not dropped).
    """
    A = limit_map[rows]
    A_free = A[:, free].tocsr()
    A_free_t = sp.block_diag([A_free.T] * 3, format="csr")  # x, y, z blocks
    fixed = A @ V0 - A_free @ V0[free]
    V = V0.copy()
    for _ in range(CREASE.rounds):
        X = A @ V
        foot, tangent = curves.closest(X, chain)
        across = np.eye(3)[None] - tangent[:, :, None] * tangent[:, None, :]  # (r, 3, 3)
        weight = across + CREASE.along_weight * np.eye(3)[None]
        target = np.einsum("rab,rb->ra", across, foot) + CREASE.along_weight * along
        blocks = [[sp.diags(weight[:, a, b]) @ A_free for b in range(3)] for a in range(3)]
        system = sp.bmat(blocks, format="csr")
        # minimise sum_j (X_j - foot_j)^T across_j (X_j - foot_j) + w |X_j - along_j|^2
        lhs = A_free_t @ system + CREASE.damping * sp.identity(3 * len(free))
        rhs = (A_free_t @ (target - np.einsum("rab,rb->ra", weight, fixed)).T.reshape(-1)
               + CREASE.damping * V0[free].T.reshape(-1))
        move = spsolve(lhs.tocsc(), rhs).reshape(3, -1).T - V0[free]
        length = np.linalg.norm(move, axis=1)
        move *= np.minimum(1.0, reach / np.maximum(length, 1e-300))[:, None]
        V[free] = V0[free] + move
    return V


class _Polylines:
    """The feature polylines of the matched chains, for closest points per chain."""

    def __init__(self, polylines):
        self.start = np.concatenate([p[:-1] for p in polylines])
        self.stop = np.concatenate([p[1:] for p in polylines])
        self.owner = np.concatenate([np.full(len(p) - 1, k) for k, p in enumerate(polylines)])
        self.first = np.searchsorted(self.owner, np.arange(len(polylines)))

    def closest(self, points, chain):
        """Closest points ((r, 3)) of ``points`` ((r, 3)) on the polylines of ``chain``
        ((r,) int64) and the unit tangents ((r, 3)) of the segments they lie on."""
        counts = np.bincount(self.owner, minlength=len(self.first))[chain]
        row = np.repeat(np.arange(len(points)), counts)
        segment = np.repeat(self.first[chain] - np.cumsum(np.r_[0, counts[:-1]]), counts) \
            + np.arange(len(row))
        a, b = self.start[segment], self.stop[segment]
        d = b - a
        t = np.clip(np.einsum("ij,ij->i", points[row] - a, d)
                    / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        foot = a + t[:, None] * d
        distance = np.linalg.norm(points[row] - foot, axis=1)
        order = np.lexsort((distance, row))
        best = order[np.r_[True, row[order][1:] != row[order][:-1]]]
        tangent = d[best] / np.maximum(np.linalg.norm(d[best], axis=1), 1e-300)[:, None]
        return foot[best], tangent


def _fine_chains(fine, n, creases):
    """{(a, b): fine vertices from a to b} for each base crease edge ``a < b``: the fine
    crease vertices strictly between its two ends, in order from ``a``."""
    pairs = np.asarray(fine.creases, dtype=np.int64).reshape(-1, 2)
    neighbours = {}
    for u, v in pairs.tolist():
        neighbours.setdefault(u, []).append(v)
        neighbours.setdefault(v, []).append(u)
    wanted = set(map(tuple, creases.tolist()))
    chains = {}
    for a in np.unique(creases).tolist():
        for step in neighbours.get(a, ()):
            inner, previous, current = [], a, step
            while current >= n:
                inner.append(current)
                following = [w for w in neighbours[current] if w != previous]
                previous, current = current, following[0]
            key = (a, current)
            if a < current and key in wanted:
                chains[key] = inner
    return chains


def _target_vertex_of(V, target_vertices):
    """(n,) int64 the target vertex each of ``V`` sits on (nearer than
    ``core.tolerances.CONTACT`` times the target's bounding-box diagonal: the decimation
    copies the target's coordinates), -1 where none."""
    diagonal = float(np.linalg.norm(np.ptp(target_vertices, axis=0)))
    distance, index = cKDTree(target_vertices).query(V)
    return np.where(distance <= CONTACT * diagonal, index, -1)


class _FeatureGraph:
    """The target's closed feature network (:func:`core.quadmesh.creases.feature_edges`,
    :func:`core.quadmesh.creases.closed_network`) as a weighted graph on its vertices."""

    def __init__(self, vertices, faces):
        edges = closed_network(feature_edges(vertices, faces, CREASE_ANGLE), len(vertices))
        edges = np.zeros((0, 2), dtype=np.int64) if edges is None else edges
        self.nodes = np.unique(edges)
        local = np.searchsorted(self.nodes, edges)
        length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
        k = len(self.nodes)
        self.graph = sp.coo_matrix((length, (local[:, 0], local[:, 1])), shape=(k, k)).tocsr()
        self.vertices = vertices

    def paths(self, pairs, ends):
        """For each target vertex pair ``(a, b)`` of ``pairs`` ((p, 2) int64), the target
        vertices of the shortest feature chain from ``a`` to ``b``, or None when ``a`` or
        ``b`` is -1 or not on the network, when no chain is within ``CREASE.path_reach`` times their
        distance, or when the shortest passes through another vertex of ``ends`` (set).
        One Dijkstra search per distinct start, as far as the farthest pair's reach."""
        found = [None] * len(pairs)
        if not len(self.nodes) or not len(pairs):
            return found
        local = np.minimum(np.searchsorted(self.nodes, pairs), len(self.nodes) - 1)
        usable = ((pairs >= 0).all(axis=1) & (pairs[:, 0] != pairs[:, 1])
                  & (self.nodes[local] == pairs).all(axis=1))
        reach = CREASE.path_reach * np.linalg.norm(self.vertices[pairs[:, 0]]
                                            - self.vertices[pairs[:, 1]], axis=1)
        if not usable.any():
            return found
        starts, row = np.unique(local[usable, 0], return_inverse=True)
        distance, previous = dijkstra(self.graph, directed=False, indices=starts,
                                      limit=float(reach[usable].max()),
                                      return_predecessors=True)
        for k, r in zip(np.flatnonzero(usable), row):
            la, lb = local[k]
            if not distance[r, lb] <= reach[k]:
                continue
            chain = [lb]
            while chain[-1] != la:
                chain.append(previous[r, chain[-1]])
            path = self.nodes[np.asarray(chain[::-1])]
            if not ends.intersection(path[1:-1].tolist()):
                found[k] = path
        return found


def _along(polyline, fractions):
    """(k, 3) points at arc-length ``fractions`` ((k,) in [0, 1]) of a (p, 3) polyline."""
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0),
                                                             axis=1))])
    s = fractions * length[-1]
    return np.column_stack([np.interp(s, length, polyline[:, k]) for k in range(3)])

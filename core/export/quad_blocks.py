# SPDX-License-Identifier: LGPL-2.1-or-later
"""A closed quad mesh partitioned into rectangular blocks of quads (its motorcycle graph).

Method
------
Every extraordinary vertex (valence ``n != 4``) sends a "motorcycle" along every other edge
around it (``ceil(n / 2)`` of them; Eppstein et al., "Motorcycle graphs: canonical quad mesh
partitioning", send one along each): between two of its trails lie one quad (the vertex is a
block corner) or two (it lies on a straight block side). Motorcycles advance one edge per
round, all together, and go straight through valence-4 vertices (to the edge opposite the one
they arrived by); one stops on reaching a vertex that a trail already passes through, or an
extraordinary vertex, or an edge another one has taken. The trails cut the mesh into regions
whose interiors hold valence-4 vertices only, so each region is a grid of quads; with
extraordinary vertices around it it is a rectangle. A region that is not
a plain rectangle (an annulus or a torus of regular quads with no extraordinary vertex to cut
it, or a rectangle whose sides touch each other) gets a *seed*: its interior vertex farthest
from every trail starts four motorcycles of its own, and the graph is traced again. A region
with no interior vertex left is cut into single quads.

Sharp crease edges are trails from the start (every crease becomes a B-rep edge, and no
motorcycle crosses one), and the ends and corners of crease lines (vertices with one crease
edge or three or more) send motorcycles like extraordinary vertices.

A block's sides run along trails; a block corner of one block may lie inside a side of a
neighbour (a T-junction where a motorcycle stopped), so the B-rep splits block sides at
every block corner on them (:mod:`core.export.chart_faces`).
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from core.errors import InternalError
from core.subdivision.catmull_clark import crease_edge_mask, mesh_topology, vertex_crease_counts

STEP_OF_SIDE = np.array([[0, -1], [1, 0], [0, 1], [-1, 0]])
"""(4, 2) grid step across a block-aligned side: side ``k - rotation`` of a quad faces
``v = min`` (0), ``u = max`` (1), ``v = max`` (2), ``u = min`` (3) of its cell."""


@dataclass
class QuadBlock:
    """One rectangular block of quads.

    quads : (W, H) int64 quad in each cell, ``[i, j]`` the cell ``i`` along the block's ``u``
        and ``j`` along its ``v``.
    rotation : (W, H) int64 local corner of each quad that lies at the cell's ``(i, j)``
        grid vertex (its corner ``rotation + 1`` lies at ``(i + 1, j)``; quads and blocks
        turn the same way, so the block's ``d/du x d/dv`` is the quads' normal).
    vertices : (W + 1, H + 1) int64 mesh vertex at each grid vertex (all distinct).
    """

    quads: np.ndarray
    rotation: np.ndarray
    vertices: np.ndarray


@dataclass
class QuadBlocks:
    """The block partition of a quad mesh.

    blocks : list of :class:`QuadBlock`, every quad in exactly one.
    cut_edge : (n_edges,) bool, the mesh edge (``mesh_topology`` numbering) lies on a trail.
    n_seeds : int, seed vertices that were added to cut regions of regular quads.
    """

    blocks: list
    cut_edge: np.ndarray
    n_seeds: int


def _straight(topo, corner):
    """The half-edge (corner) continuing half-edge ``corner`` straight through the valence-4
    vertex it arrives at: two edges on around that vertex."""
    return topo.next_corner[topo.twin[topo.next_corner[corner]]]


def _source_corners(topo, fv, sources, every_edge=False):
    """(k,) int64 outgoing half-edges (corners) on which the vertices ``sources`` start
    motorcycles: every other edge around each (valence ``n >= 3``), so that between two
    trails lie one or two quads; every edge at valence <= 2 or with ``every_edge`` (seeds)."""
    first = np.full(int(fv.max()) + 1, -1, dtype=np.int64)
    first[fv[::-1]] = np.arange(len(fv))[::-1]
    out = []
    for v in np.asarray(sources).tolist():
        ring = [int(first[v])]
        while True:
            c = int(topo.twin[topo.prev_corner[ring[-1]]])
            if c == ring[0]:
                break
            ring.append(c)
        out += ring if every_edge or len(ring) <= 2 else ring[::2]
    return np.array(out, dtype=np.int64)


def _trace(topo, fv, sources, seeds, n_vertices, crease):
    """(n_edges,) bool edges on the motorcycle trails started at the extraordinary vertices
    ``sources`` (every other edge) and the valence-4 ``seeds`` (every edge), all advancing one
    edge per round; the ``crease`` edges (n_edges,) bool are trails from the start."""
    cut = crease.copy()
    on_trail = np.zeros(n_vertices, dtype=bool)
    on_trail[topo.edges[crease].reshape(-1)] = True
    on_trail[sources] = True
    on_trail[seeds] = True
    active = np.concatenate([_source_corners(topo, fv, sources),
                             _source_corners(topo, fv, seeds, every_edge=True)]).tolist()
    while active:
        moving = []
        for c in active:
            e = topo.corner_edge[c]
            if cut[e]:
                continue
            cut[e] = True
            v = fv[topo.next_corner[c]]
            if on_trail[v]:
                continue
            on_trail[v] = True
            moving.append(int(_straight(topo, c)))
        active = moving
    return cut


def _regions(topo, n_quads, cut):
    """(n_quads,) int64 region of each quad: quads joined across edges off the trails."""
    c = np.flatnonzero(~cut[topo.corner_edge])
    graph = sp.coo_matrix((np.ones(len(c)), (c // 4, topo.twin[c] // 4)), shape=(n_quads, n_quads))
    return connected_components(graph, directed=False)[1]


def _grid_of(topo, fv, valence, cut, quads):
    """The :class:`QuadBlock` of a region of quads, or None when it is not a plain rectangle
    with distinct grid vertices, valence 4 inside and no trail inside.

    Quads are laid out from the first by walking across uncut edges: a quad's neighbour
    across its side ``k`` sits one cell towards ``STEP_OF_SIDE[k - rotation]``.
    """
    start = int(quads[0])
    cell = {start: (0, 0, 0)}
    stack = [start]
    while stack:
        q = stack.pop()
        i, j, r = cell[q]
        for k in range(4):
            c = 4 * q + k
            if cut[topo.corner_edge[c]]:
                continue
            t = int(topo.twin[c])
            g, kk = t // 4, t % 4
            di, dj = STEP_OF_SIDE[(k - r) % 4]
            place = (i + di, j + dj, (kk - (k - r + 2)) % 4)
            known = cell.get(g)
            if known is None:
                cell[g] = place
                stack.append(g)
            elif known != place:
                return None
    ids = np.fromiter(cell.keys(), dtype=np.int64)
    ijr = np.array(list(cell.values()), dtype=np.int64)
    i, j = ijr[:, 0] - ijr[:, 0].min(), ijr[:, 1] - ijr[:, 1].min()
    W, H = int(i.max()) + 1, int(j.max()) + 1
    if W * H != len(ids):
        return None
    grid = np.full((W, H), -1, dtype=np.int64)
    grid[i, j] = ids
    if (grid < 0).any():
        return None
    rotation = np.zeros((W, H), dtype=np.int64)
    rotation[i, j] = ijr[:, 2]
    verts = np.full((W + 1, H + 1), -1, dtype=np.int64)
    for di, dj, k in ((0, 0, 0), (1, 0, 1), (1, 1, 2), (0, 1, 3)):
        v = fv[4 * ids + (ijr[:, 2] + k) % 4]
        old = verts[i + di, j + dj]
        if ((old >= 0) & (old != v)).any():
            return None
        verts[i + di, j + dj] = v
    if len(np.unique(verts)) != verts.size or (valence[verts[1:-1, 1:-1]] != 4).any():
        return None
    inner = np.concatenate([4 * grid[1:, :] + (rotation[1:, :] + 3) % 4,
                            4 * grid[:, 1:] + rotation[:, 1:] % 4], axis=None)
    if cut[topo.corner_edge[inner]].any():
        return None
    return QuadBlock(grid, rotation, verts)


def _seed(topo, fv, cut, quads, n_vertices):
    """The interior vertex of a region (on no trail) farthest from every trail, by hops
    along mesh edges; None if the region has none."""
    on_trail = np.zeros(n_vertices, dtype=bool)
    on_trail[topo.edges[cut].reshape(-1)] = True
    own = np.unique(fv[(4 * quads[:, None] + np.arange(4)).reshape(-1)])
    candidates = own[~on_trail[own]]
    if not len(candidates):
        return None
    if not on_trail.any():
        return int(candidates.min())
    e = topo.edges
    graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    hops = dijkstra(graph, directed=False, unweighted=True, indices=np.flatnonzero(on_trail),
                    min_only=True)
    return int(candidates[np.argmax(hops[candidates])])


def quad_blocks(quads):
    """Partition a closed quad mesh into rectangular blocks along its motorcycle graph.

    Parameters
    ----------
    quads : PolyMesh, closed 2-manifold, every face a quad, possibly with crease edges.

    Returns
    -------
    QuadBlocks
    """
    fv = quads.face_vertices
    n_vertices, n_quads = len(quads.vertices), quads.n_faces
    topo = mesh_topology(fv, quads.face_offsets, n_vertices)
    valence = np.bincount(fv, minlength=n_vertices)
    crease = crease_edge_mask(topo, quads.creases)
    n_crease = vertex_crease_counts(topo, crease, n_vertices)
    sources = np.flatnonzero((valence != 4) | (n_crease == 1) | (n_crease >= 3))
    sources = sources[valence[sources] > 0]
    forced = np.zeros(len(topo.edges), dtype=bool)
    seeds = []
    while True:
        cut = _trace(topo, fv, sources, np.array(seeds, dtype=np.int64), n_vertices,
                     crease) | forced
        region = _regions(topo, n_quads, cut)
        blocks, added = [], False
        for r in range(int(region.max()) + 1):
            members = np.flatnonzero(region == r)
            block = _grid_of(topo, fv, valence, cut, members)
            if block is not None:
                blocks.append(block)
                continue
            seed = _seed(topo, fv, cut, members, n_vertices)
            if seed is None:
                forced[topo.corner_edge[(4 * members[:, None] + np.arange(4)).reshape(-1)]] = True
            else:
                seeds.append(seed)
            added = True
        if not added:
            return QuadBlocks(blocks, cut, len(seeds))


def base_face_blocks(base, quads):
    """Partition the first Catmull-Clark refinement ``quads`` of a polygon mesh ``base`` into
    one block per base face: the 2 x 2 quads of each base quad, and each quad of a face with
    ``n != 4`` corners on its own.

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold polygon mesh with at least one non-quad face.
    quads : PolyMesh, its level-1 refinement (face ``fo[f] + k`` the quad at corner ``k`` of
        base face ``f``, as :func:`core.subdivision.catmull_clark.subdivide` numbers them).

    Returns
    -------
    QuadBlocks whose cut edges are every edge of ``quads`` but those inside a base quad.

    Raises
    ------
    InternalError when a base face's refined quads do not form its block (``quads`` is not
    the refinement of ``base``).
    """
    fv = quads.face_vertices
    n_vertices = len(quads.vertices)
    topo = mesh_topology(fv, quads.face_offsets, n_vertices)
    valence = np.bincount(fv, minlength=n_vertices)
    parent = mesh_topology(base.face_vertices, base.face_offsets,
                           len(base.vertices)).face_of_corner
    corner = np.arange(len(fv))
    is_quad = base.face_sizes == 4
    inside = (parent[corner // 4] == parent[topo.twin[corner] // 4]) & is_quad[parent[corner // 4]]
    cut = np.ones(len(topo.edges), dtype=bool)
    cut[topo.corner_edge[inside]] = False
    blocks = []
    offsets = np.asarray(base.face_offsets, dtype=np.int64)
    for f, size in enumerate(base.face_sizes.tolist()):
        children = np.arange(offsets[f], offsets[f + 1], dtype=np.int64)
        groups = [children] if size == 4 else [children[k:k + 1] for k in range(size)]
        for members in groups:
            block = _grid_of(topo, fv, valence, cut, members)
            if block is None:
                raise InternalError(f"the refined quads of base face {f} do not form a block")
            blocks.append(block)
    return QuadBlocks(blocks, cut, 0)

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Per-quad B-spline patches merged into one multi-span face per rectangular block of quads.

Method
------
The blocks are those of :func:`core.export.quad_blocks.quad_blocks` (the quad mesh cut along
its motorcycle graph). A block of ``W x H`` quads becomes one clamped bicubic B-spline on
``[0, 1]^2``, quad ``(i, j)`` on ``[i / W, (i + 1) / W] x [j / H, (j + 1) / H]``:

1. each quad's patch is turned into the block's orientation (its pole grid rotated, knots
   reversed where a direction flips);
2. every patch of a column of quads is refined (knot insertion, exact) to the union of the
   column's interior knots, every patch of a row to the row's, so the patches of one column
   share their ``u`` knots and those of one row their ``v`` knots;
3. the patches are joined into one pole grid with triple knots (C0) at the quad boundaries:
   this spline *is* the per-quad surface;
4. interior knots are removed where the surface is smooth there
   (:func:`core.export.spline_knots.remove_knots`, half of :data:`MERGE_TOLERANCE` per
   direction): the joins of regular quads (C2), of the G1 export's patches inside a block
   (C1: the connection is C1 away from extraordinary vertices). A knot line stays triple
   where the patches meet only G1 (through an extraordinary vertex inside a block side).

The B-rep edges run along block sides, split at every B-rep vertex on them: the block
corners and the vertices where three or more trails meet (where a neighbour's corner makes a
T-junction), so every edge separates the same two faces along its whole length and is used
once by each. An edge's curve is its per-quad edge curves joined and reduced the same way,
so it lies within :data:`MERGE_TOLERANCE` of both faces along its parameter lines (straight
segments of the faces' ``(u, v)``).
"""
import numpy as np

from core.export.brep_topology import BRepTopology, EdgeCurve
from core.export.quad_blocks import quad_blocks
from core.export.spline_knots import join, refine, remove_knots
from core.subdivision.catmull_clark import mesh_topology
from core.tolerances import BREP_MM
from core.types import BSplinePatch, PatchSet

MERGE_TOLERANCE = 0.1 * BREP_MM
"""Largest distance (mm) between a merged face or edge curve and the per-quad surface it
replaces; a tenth of the B-rep tolerance, so a face and the curve of an edge it shares with
another face stay within the tolerance of each other."""


def _reversed_knots(knots, mults):
    return 1.0 - np.asarray(knots, dtype=np.float64)[::-1], np.asarray(mults)[::-1]


def _rotate(patch, turns):
    """(poles (nu, nv, 3), (u knots, mults), (v knots, mults)) of ``patch`` reparametrised by
    ``turns`` quarter turns: one turn is ``new(a, b) = old(1 - b, a)``, so after ``r`` turns
    the patch's corner ``r`` lies at ``(a, b) = (0, 0)``."""
    P = np.asarray(patch.poles)
    u = (np.asarray(patch.u_knots, dtype=np.float64), np.asarray(patch.u_mults))
    v = (np.asarray(patch.v_knots, dtype=np.float64), np.asarray(patch.v_mults))
    for _ in range(turns):
        P = P[::-1].transpose(1, 0, 2)
        u, v = v, _reversed_knots(*u)
    return P, u, v


def _interior_union(knot_sets):
    """(knots, mults) on [0, 1]: the union of the interior knots of clamped knot vectors
    (largest multiplicity of each), with the clamped ends."""
    most = {}
    for knots, mults in knot_sets:
        for k, m in zip(np.asarray(knots)[1:-1].tolist(), np.asarray(mults)[1:-1].tolist()):
            most[k] = max(most.get(k, 0), int(m))
    inner = sorted(most)
    return (np.array([0.0] + inner + [1.0]),
            np.array([4] + [most[k] for k in inner] + [4], dtype=np.int64))


def _block_surface(patches, block, tolerance):
    """One BSplinePatch on [0, 1]^2 for a block of quad patches, and the bound of its
    distance to them (model units)."""
    W, H = block.quads.shape
    cells = [[_rotate(patches[block.quads[i, j]], int(block.rotation[i, j])) for j in range(H)]
             for i in range(W)]
    cols = [_interior_union([cells[i][j][1] for j in range(H)]) for i in range(W)]
    rows = [_interior_union([cells[i][j][2] for i in range(W)]) for j in range(H)]
    columns = []
    for i in range(W):
        strips = []
        for j in range(H):
            P, (uk, um), (vk, vm) = cells[i][j]
            P = refine(P, uk, um, *cols[i])
            P = refine(P.transpose(1, 0, 2), vk, vm, *rows[j])
            strips.append((P, *rows[j]))
        Pv, vk, vm = join(strips)
        columns.append((Pv.transpose(1, 0, 2), *cols[i]))
    P, uk, um = join(columns)
    P, uk, um, err_u = remove_knots(P, uk, um, 0.5 * tolerance)
    Q, vk, vm, err_v = remove_knots(P.transpose(1, 0, 2), vk, vm, 0.5 * tolerance)
    return BSplinePatch(np.ascontiguousarray(Q.transpose(1, 0, 2)), uk, um, vk, vm), err_u + err_v


def _side_corners(block):
    """Four (n_k,) int64 arrays: the half-edges (corners) along the block's sides in loop
    order (side 0 along ``v = 0`` from ``(0, 0)``, then ``u = 1``, ``v = 1``, ``u = 0``)."""
    W, H = block.quads.shape
    g, r = block.quads, block.rotation
    return [4 * g[:, 0] + r[:, 0] % 4,
            4 * g[W - 1, :] + (r[W - 1, :] + 1) % 4,
            (4 * g[:, H - 1] + (r[:, H - 1] + 2) % 4)[::-1],
            (4 * g[0, :] + (r[0, :] + 3) % 4)[::-1]]


def _side_uv(side, s):
    """(u, v) of position ``s`` in [0, 1] along block side ``side`` (loop order)."""
    return ((s, 0.0), (1.0, s), (1.0 - s, 1.0), (0.0, 1.0 - s))[side]


def _edge_curve(quad_topology, vertex_of_mesh, fv, topo, chain, tolerance):
    """The EdgeCurve along a chain of half-edges: the per-quad edge curves joined, knots
    removed within ``tolerance``; and the bound of its distance to them."""
    pieces = []
    for c in chain.tolist():
        e = int(topo.corner_edge[c])
        curve = quad_topology.edge_curves[e]
        poles, knots, mults = curve.poles, curve.knots, curve.mults
        if quad_topology.edge_vertices[e, 0] != vertex_of_mesh[fv[c]]:
            poles = poles[::-1]
            knots, mults = _reversed_knots(knots, mults)
        pieces.append((poles, knots, mults))
    poles, knots, mults = join(pieces) if len(pieces) > 1 else pieces[0]
    poles, knots, mults, err = remove_knots(poles, knots, mults, tolerance)
    return EdgeCurve(np.ascontiguousarray(poles), knots, np.asarray(mults, dtype=np.int64)), err


def chart_patches(quad_patches, quads, tolerance=MERGE_TOLERANCE, partition=None):
    """Merge one-patch-per-quad B-spline patches into one face per rectangular block of quads.

    Parameters
    ----------
    quad_patches : PatchSet with one patch per quad of ``quads`` (patch ``f`` on quad ``f``,
        ``d/du x d/dv`` along the quads' orientation) and its ``topology`` (one B-rep edge
        per mesh edge, ``mesh_topology`` numbering; one vertex per used mesh vertex in
        increasing order), as :func:`core.export.g1_patches.g1_surface_patches` makes.
    quads : PolyMesh, closed 2-manifold, all quads.
    tolerance : float, largest distance of a face or edge curve from the per-quad surface
        (model units; default :data:`MERGE_TOLERANCE`).
    partition : QuadBlocks or None, the blocks to merge (default
        :func:`core.export.quad_blocks.quad_blocks` of ``quads``).

    Returns
    -------
    PatchSet
        One patch per block on ``[0, 1]^2``; ``face_of_patch`` the quad-patch's
        ``face_of_patch`` of the block's first quad; ``topology`` the block faces' shared
        edges; ``info`` a copy of the per-quad one with ``faces`` ("chart"), ``n_faces``,
        ``n_patches``, ``n_poles``, ``n_seeds`` (regular vertices added to cut regions
        without extraordinary vertices) and ``merge_error`` (bound of the distance between
        the faces and the per-quad patches, model units).
    """
    fv = quads.face_vertices
    topo = mesh_topology(fv, quads.face_offsets, len(quads.vertices))
    partition = quad_blocks(quads) if partition is None else partition
    blocks = partition.blocks
    qt = quad_patches.topology
    used = np.unique(fv)
    vertex_of_mesh = np.full(len(quads.vertices), -1, dtype=np.int64)
    vertex_of_mesh[used] = np.arange(len(used))
    faces, worst = [], 0.0
    for block in blocks:
        face, err = _block_surface(quad_patches.patches, block, tolerance)
        faces.append(face)
        worst = max(worst, err)
    is_vertex = np.zeros(len(quads.vertices), dtype=bool)
    for block in blocks:
        is_vertex[block.vertices[[0, -1, -1, 0], [0, 0, -1, -1]]] = True
    cut_degree = np.bincount(topo.edges[partition.cut_edge].reshape(-1), minlength=len(is_vertex))
    is_vertex |= cut_degree > 2
    brep_vertex = np.full(len(quads.vertices), -1, dtype=np.int64)
    brep_vertex[is_vertex] = np.arange(int(is_vertex.sum()))
    edge_of_key, curves, edge_vertices = {}, [], []
    use_face, use_edge, use_reversed, use_uv = [], [], [], []
    for f, block in enumerate(blocks):
        for side, chain in enumerate(_side_corners(block)):
            starts = fv[chain]
            n = len(chain)
            bounds = np.append(np.flatnonzero(is_vertex[starts]), n)  # starts at a corner
            for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
                piece = chain[a:b]
                key = int(topo.corner_edge[piece].min())
                edge = edge_of_key.get(key)
                if edge is None:
                    edge = edge_of_key[key] = len(curves)
                    curve, err = _edge_curve(qt, vertex_of_mesh, fv, topo, piece, tolerance)
                    worst = max(worst, err)
                    curves.append(curve)
                    edge_vertices.append((brep_vertex[fv[piece[0]]],
                                          brep_vertex[fv[topo.next_corner[piece[-1]]]]))
                    use_reversed.append(False)
                else:
                    use_reversed.append(True)
                use_face.append(f)
                use_edge.append(edge)
                use_uv.append((_side_uv(side, a / n), _side_uv(side, b / n)))
    use_uv = np.array(use_uv, dtype=np.float64)
    use_reversed = np.array(use_reversed)
    use_uv[use_reversed] = use_uv[use_reversed][:, ::-1]
    vertices = qt.vertices[vertex_of_mesh[np.flatnonzero(is_vertex)]]
    topology = BRepTopology(vertices, np.array(edge_vertices, dtype=np.int64), curves,
                            np.array(use_face, dtype=np.int64), np.array(use_edge, dtype=np.int64),
                            use_reversed, use_uv)
    info = dict(quad_patches.info)
    info.update({"faces": "chart", "n_faces": len(faces), "n_patches": len(faces),
                 "n_poles": int(sum(p.poles.shape[0] * p.poles.shape[1] for p in faces)),
                 "n_seeds": int(partition.n_seeds), "merge_error": float(worst)})
    first = np.array([b.quads[0, 0] for b in blocks], dtype=np.int64)
    return PatchSet(faces, np.asarray(quad_patches.face_of_patch)[first], info, topology)

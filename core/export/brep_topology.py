# SPDX-License-Identifier: LGPL-2.1-or-later
"""The shared-edge boundary topology of a closed set of B-spline patches.

A :class:`BRepTopology` lists every B-rep vertex and edge once: an edge is one 3-D
B-spline curve between two vertices, used by exactly two faces (patches), once in
each direction. Each use carries its parameter line on the face's patch (a straight
segment in ``(u, v)``), so a CAD kernel can build the shell from these edges directly
instead of sewing faces by tolerance.

:func:`topology_from_sides` derives the topology of patches whose neighbours share
whole sides with bit-identical boundary poles (one edge per side pair); the exporter
(:mod:`core.export.bspline`) builds its own, where a side may be split into several
edges. :func:`check_topology` verifies either kind in numpy.
"""
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from core.errors import ExportError
from core.export.bspline_basis import basis_matrix, evaluate_patch_points
from core.mesh_topology import next_corners

SIDE_NAMES = ("v=min", "u=max", "v=max", "u=min")
"""Patch sides in loop order (counter-clockwise in ``(u, v)``): side ``k`` runs from
patch corner ``k`` to corner ``k + 1``, corners being (0,0), (1,0), (1,1), (0,1)."""
CORNER_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


@dataclass
class EdgeCurve:
    """A clamped 3-D B-spline curve on ``[0, 1]`` (OpenCascade form).

    poles : (n, 3) float64; knots : (k,) strictly increasing, 0 to 1; mults : (k,) int64.
    """

    poles: np.ndarray
    knots: np.ndarray
    mults: np.ndarray
    degree: int = 3


@dataclass
class BRepTopology:
    """Vertices, edges and face loops of a closed patch set.

    vertices : (nv, 3) float64 B-rep vertex points.
    edge_vertices : (ne, 2) int64 start and end vertex of each edge's curve.
    edge_curves : list of ne :class:`EdgeCurve`, parameter 0 at the start vertex.
    use_face : (nu,) int64 patch of each edge use; the uses of one patch are contiguous
        and in loop order (counter-clockwise in the patch's ``(u, v)``).
    use_edge : (nu,) int64 edge of each use.
    use_reversed : (nu,) bool, the loop runs along the edge from its end to its start.
    use_uv : (nu, 2, 2) float64 ``(u, v)`` on the patch of the edge's start and end
        vertex; the edge's parameter line is the segment between them, linear in the
        curve parameter.
    """

    vertices: np.ndarray
    edge_vertices: np.ndarray
    edge_curves: list
    use_face: np.ndarray
    use_edge: np.ndarray
    use_reversed: np.ndarray
    use_uv: np.ndarray

    @property
    def n_faces(self):
        return int(self.use_face.max()) + 1 if len(self.use_face) else 0

    def loop_offsets(self):
        """(n_faces + 1,) int64 start of each face's uses in the use arrays."""
        counts = np.bincount(self.use_face, minlength=self.n_faces)
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _side_rows(poles):
    """The four boundary pole rows of a patch in loop order (corner k to corner k+1)."""
    return (poles[:, 0], poles[-1, :], poles[::-1, -1], poles[0, ::-1])


def topology_from_sides(patches):
    """Topology of patches that share whole sides with bit-identical poles.

    Parameters
    ----------
    patches : list of core.types.BSplinePatch, closed and consistently oriented:
        each side's pole row equals exactly one other side's row, in reverse order.

    Returns
    -------
    BRepTopology with one edge per pair of matching sides (the curve of the first
    side met) and one vertex per distinct corner point.

    Raises
    ------
    ExportError
        A side has no partner or more than one (the message names the patch and side),
        or the patches are not consistently oriented.
    """
    rows, keys = [], {}
    for p, patch in enumerate(patches):
        for s, row in enumerate(_side_rows(np.asarray(patch.poles, dtype=np.float64))):
            forward, backward = row.tobytes(), row[::-1].tobytes()
            keys.setdefault(min(forward, backward), []).append((len(rows), forward <= backward))
            rows.append((p, s, row))
    n_sides = len(rows)
    use_edge = np.empty(n_sides, dtype=np.int64)
    use_reversed = np.empty(n_sides, dtype=bool)
    curves, owners = [], []
    for members in keys.values():
        if len(members) != 2 or members[0][1] == members[1][1]:
            p, s, _ = rows[members[0][0]]
            what = ("has no partner side with bit-identical poles" if len(members) == 1 else
                    f"is shared by {len(members)} sides" if len(members) > 2 else
                    "runs in the same direction as its partner (inconsistent orientation)")
            raise ExportError(f"cannot build the shell topology: patch {p} side "
                              f"{SIDE_NAMES[s]} {what}")
        (first, first_fwd), (second, _) = members
        p, s, row = rows[first]
        patch = patches[p]
        knots, mults, degree = ((patch.u_knots, patch.u_mults, patch.degree_u) if s % 2 == 0
                                else (patch.v_knots, patch.v_mults, patch.degree_v))
        if s >= 2:
            knots = 1.0 - np.asarray(knots, dtype=np.float64)[::-1]
            mults = np.asarray(mults)[::-1]
        edge = len(curves)
        curves.append(EdgeCurve(np.ascontiguousarray(row), np.asarray(knots, dtype=np.float64),
                                np.asarray(mults, dtype=np.int64), int(degree)))
        owners.append(first)
        use_edge[first] = use_edge[second] = edge
        use_reversed[first], use_reversed[second] = False, True
    corners = np.stack([np.asarray(p.poles, dtype=np.float64)[[0, -1, -1, 0], [0, 0, -1, -1]]
                        for p in patches]).reshape(-1, 3)
    vertices, corner_vertex = np.unique(corners, axis=0, return_inverse=True)
    corner_vertex = corner_vertex.reshape(-1)
    owners = np.asarray(owners, dtype=np.int64)
    side = np.arange(n_sides)
    start = corner_vertex[side]
    end = corner_vertex[4 * (side // 4) + (side + 1) % 4]
    edge_vertices = np.stack([start[owners], end[owners]], axis=1)
    uv = np.stack([CORNER_UV[side % 4], CORNER_UV[(side + 1) % 4]], axis=1)
    uv[use_reversed] = uv[use_reversed][:, ::-1]
    return BRepTopology(vertices, edge_vertices, curves, side // 4, use_edge, use_reversed, uv)


def check_topology(topology, patches, tolerance, samples=5):
    """Verify that a topology describes one closed, consistently oriented shell.

    Checks that every edge is used exactly twice, once in each direction; that the
    faces form one connected piece; that each
    face's loop is closed (every use ends at the vertex where the next one starts);
    that the edge curves start and end at their vertices; and that each curve and
    its parameter lines on both patches agree within ``tolerance`` at ``samples`` even
    parameters and at the middle of every knot span of the curves.

    Parameters
    ----------
    topology : BRepTopology
    patches : list of core.types.BSplinePatch, the faces.
    tolerance : float, model units.
    samples : int >= 2, even parameters per edge (span midpoints are added).

    Returns
    -------
    float, the largest distance found between an edge curve and a patch along it.

    Raises
    ------
    ExportError naming the first edge or face that fails.
    """
    t = topology
    n_edges = len(t.edge_curves)
    forward = np.bincount(t.use_edge[~t.use_reversed], minlength=n_edges)
    backward = np.bincount(t.use_edge[t.use_reversed], minlength=n_edges)
    bad = np.flatnonzero((forward != 1) | (backward != 1))
    if len(bad):
        e = int(bad[0])
        raise ExportError(f"the shell is not closed: {len(bad)} edges are not used once in each "
                          f"direction, e.g. edge {e} ({forward[e]} forward, {backward[e]} "
                          "backward uses)")
    if len(np.unique(t.use_face)) != len(patches):
        raise ExportError(f"the topology has loops for {len(np.unique(t.use_face))} of "
                          f"{len(patches)} patches")
    pair = np.argsort(t.use_edge, kind="stable").reshape(n_edges, 2)
    faces = t.use_face[pair]
    graph = coo_matrix((np.ones(n_edges), (faces[:, 0], faces[:, 1])),
                       shape=(len(patches), len(patches)))
    pieces = connected_components(graph, directed=False)[0]
    if pieces > 1:
        raise ExportError(f"the patches form {pieces} separate pieces; a solid needs one shell")
    ends = t.edge_vertices[t.use_edge]
    loop_start = np.where(t.use_reversed, ends[:, 1], ends[:, 0])
    loop_end = np.where(t.use_reversed, ends[:, 0], ends[:, 1])
    offsets = t.loop_offsets()
    nxt = next_corners(offsets)
    open_use = np.flatnonzero(loop_end != loop_start[nxt])
    if len(open_use):
        u = int(open_use[0])
        raise ExportError(f"the boundary loop of patch {t.use_face[u]} is not closed: its edge "
                          f"{t.use_edge[u]} ends where the next one does not start")
    layouts = {}
    for e, curve in enumerate(t.edge_curves):
        key = (curve.knots.tobytes(), curve.mults.tobytes(), curve.degree)
        layouts.setdefault(key, []).append(e)
    mids = [0.5 * (t.edge_curves[m[0]].knots[1:] + t.edge_curves[m[0]].knots[:-1])
            for m in layouts.values()]
    param = np.unique(np.concatenate([np.linspace(0.0, 1.0, samples)] + mids))
    samples = len(param)
    curve_pts = np.empty((n_edges, samples, 3))
    for members in layouts.values():
        c0 = t.edge_curves[members[0]]
        B = basis_matrix(c0.knots, c0.mults, param, degree=c0.degree)
        poles = np.stack([t.edge_curves[e].poles for e in members])
        curve_pts[members] = np.einsum("ti,eik->etk", B, poles)
    gap = np.linalg.norm(curve_pts[:, [0, -1]] - t.vertices[t.edge_vertices], axis=2).max(axis=1)
    worst = float(gap.max())
    if worst > tolerance:
        e = int(np.argmax(gap))
        raise ExportError(f"edge {e}'s curve ends {worst:.3g} away from its vertices "
                          f"(tolerance {tolerance:.3g})")
    uv = t.use_uv[:, 0, None, :] + param[None, :, None] * (t.use_uv[:, 1] - t.use_uv[:, 0])[:, None]
    on_face = evaluate_patch_points(patches, np.repeat(t.use_face, samples), uv[..., 0].reshape(-1),
                                    uv[..., 1].reshape(-1)).reshape(-1, samples, 3)
    dist = np.linalg.norm(on_face - curve_pts[t.use_edge], axis=2).max(axis=1)
    if dist.max() > tolerance:
        u = int(np.argmax(dist))
        raise ExportError(f"edge {t.use_edge[u]} lies {dist[u]:.3g} away from patch "
                          f"{t.use_face[u]} along its parameter line (tolerance {tolerance:.3g})")
    return max(worst, float(dist.max()))

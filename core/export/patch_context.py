# SPDX-License-Identifier: LGPL-2.1-or-later
"""The patch mesh of a base mesh with its exact limit surface: what fitting B-spline patches
(:mod:`core.export.bspline`) and measuring them (:mod:`core.export.bspline_measure`) share.
"""
import numpy as np
from scipy.sparse.csgraph import connected_components
import scipy.sparse as sp

from core.export.bspline_basis import BEZIER, GRADED
from core.export.patch_mesh import build_patch_mesh
from core.subdivision.catmull_clark import crease_edge_mask, mesh_topology
from core.subdivision.limit import LimitEvaluator, corner_frame, limit_matrices


class PatchContext:
    """Topology and exact-evaluation data shared by fitting and measurement.

    Parameters
    ----------
    base : core.types.PolyMesh, closed 2-manifold polygon mesh.
    depth : int, grading depth of the patches (``core.params.EXPORT_DEPTH`` by default
        in :func:`core.export.bspline.limit_surface_patches`).

    Attributes hold the patch mesh (``pm``, ``level``, ``face_of_patch``), the exact
    evaluator and the limit positions and normals of the work mesh (``limit``, ``normal``,
    ``is_ev``, ``on_crease``: a crease edge ends there, so its normal is one side's only),
    the patch mesh's edge tables (``topo``, ``edge_corner``, ``crease_edge``: the B-rep
    edge lies on a crease of ``base``), the knot kinds (``base_edge_kind``, ``kind_u``,
    ``kind_v``, ``face_has_ev``, ``quad_corner``) and ``bbox_diagonal``.
    """

    def __init__(self, base, depth):
        self.base = base
        self.depth = int(depth)
        pm = build_patch_mesh(base)
        self.pm = pm
        self.level = pm.level
        self.face_of_patch = pm.face_of_patch
        work = pm.work
        self.evaluator = LimitEvaluator(work)
        L, Tu, Tv = limit_matrices(work)
        self.limit = L @ work.vertices
        nrm = np.cross(Tu @ work.vertices, Tv @ work.vertices)
        self.normal = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        self.is_ev = np.bincount(work.face_vertices, minlength=len(work.vertices)) != 4
        work_topo = mesh_topology(work.face_vertices, work.face_offsets, len(work.vertices))
        self.on_crease = np.zeros(len(work.vertices), dtype=bool)
        self.on_crease[work_topo.edges[crease_edge_mask(work_topo, work.creases)]] = True
        mesh = pm.mesh
        self.topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
        n_edges = len(self.topo.edges)
        first = np.full(n_edges, -1, dtype=np.int64)
        c = np.arange(len(mesh.face_vertices), dtype=np.int64)
        first[self.topo.corner_edge[::-1]] = c[::-1]
        self.edge_corner = first
        self._knot_kinds(base)
        base_crease = crease_edge_mask(self.base_topo, base.creases)
        base_edge = pm.base_edge[first]
        self.crease_edge = (base_edge >= 0) & base_crease[np.maximum(base_edge, 0)]
        lo, hi = work.vertices.min(axis=0), work.vertices.max(axis=0)
        limit_lo, limit_hi = self.limit.min(axis=0), self.limit.max(axis=0)
        self.bbox_diagonal = float(np.linalg.norm(np.maximum(hi, limit_hi)
                                                  - np.minimum(lo, limit_lo)))

    def _knot_kinds(self, base):
        """Knot kind of every base edge (per ring of base quads) and of every patch.

        A base quad is regular when its four corners have valence 4, touch only quads and
        no crease edge (its limit surface is then one bicubic polynomial); a ring of quads
        (joined through opposite sides) gets the graded knots if any of its quads is
        not regular. Patches of non-quad faces are graded in both directions.
        """
        pm = self.pm
        fv, fo = base.face_vertices, base.face_offsets
        topo = mesh_topology(fv, fo, len(base.vertices))
        self.base_topo = topo
        quad = base.face_sizes == 4
        corner_quad = quad[topo.face_of_corner]
        valence = np.bincount(fv, minlength=len(base.vertices))
        irregular_vertex = valence != 4
        irregular_vertex[fv[~corner_quad]] = True
        irregular_vertex[topo.edges[crease_edge_mask(topo, base.creases)]] = True
        qf = np.flatnonzero(quad)
        qc = fo[qf][:, None] + np.arange(4)
        quad_edges = topo.corner_edge[qc]
        pairs = np.concatenate([quad_edges[:, [0, 2]], quad_edges[:, [1, 3]]])
        n_edges = len(topo.edges)
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                              shape=(n_edges, n_edges))
        _, ring = connected_components(graph, directed=False)
        graded_ring = np.zeros(ring.max() + 1, dtype=bool)
        irregular_quad = irregular_vertex[fv[qc]].any(axis=1)
        graded_ring[ring[quad_edges[irregular_quad].reshape(-1)]] = True
        self.base_edge_kind = np.where(graded_ring[ring], GRADED, BEZIER)
        k = pm.n_patches
        self.kind_u = np.full(k, GRADED, dtype=np.int64)
        self.kind_v = np.full(k, GRADED, dtype=np.int64)
        self.face_has_ev = np.ones(k, dtype=bool)
        whole = np.flatnonzero(pm.whole_quad)
        corner = fo[pm.face_of_patch[whole]][:, None] + np.arange(4)
        self.kind_u[whole] = self.base_edge_kind[topo.corner_edge[corner[:, 0]]]
        self.kind_v[whole] = self.base_edge_kind[topo.corner_edge[corner[:, 3]]]
        self.face_has_ev[whole] = irregular_vertex[fv[corner]].any(axis=1)
        self.quad_corner = np.full((k, 4), -1, dtype=np.int64)
        self.quad_corner[whole] = corner

    def evaluate(self, patch, u, v):
        """(p, 3) exact limit points of patches ``patch`` (p,) at parameters (p,)."""
        patch = np.asarray(patch, dtype=np.int64)
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
        face = self.pm.work_face[patch]
        if self.level == 1:
            whole = self.pm.whole_quad[patch]
            child = np.where(u >= 0.5, np.where(v >= 0.5, 2, 1), np.where(v >= 0.5, 3, 0))
            a, b = corner_frame(u, v, child)
            face = np.where(whole, face + child, face)
            u = np.where(whole, 2.0 * a, u)
            v = np.where(whole, 2.0 * b, v)
        return self.evaluator.evaluate(face, u, v)

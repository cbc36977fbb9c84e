# SPDX-License-Identifier: LGPL-2.1-or-later
"""Which patches a base mesh becomes, and the conforming polygon mesh of their edges.

One bicubic patch per base quad, whatever the other faces are; a face with ``n != 4``
corners becomes the ``n`` quads of its first Catmull-Clark refinement (corner, edge
midpoint, centre, edge midpoint). A base edge next to such a face is split at its
midpoint, and the quad patch on its other side keeps one surface but gets two B-rep
edges on that side, so its face has more than four edges and the B-rep stays
conforming (no T-junctions).

The *patch mesh* is the polygon mesh of those B-rep faces: its vertices are vertices
of the evaluation mesh (the base mesh if it is all quads, else its level-1
refinement: base vertices, then one point per base face, then one per base edge);
each face lists its patch's corners and, on split sides, the edge midpoints. Every
edge of the patch mesh is one B-rep edge.
"""
from dataclasses import dataclass

import numpy as np

from core.subdivision.catmull_clark import mesh_topology, subdivide
from core.types import PolyMesh

CORNER_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
SIDE_MID_UV = np.array([[0.5, 0.0], [1.0, 0.5], [0.5, 1.0], [0.0, 0.5]])


@dataclass
class PatchMesh:
    """Patches of a base mesh and the conforming polygon mesh of their boundaries.

    work : PolyMesh, all quads, the mesh the limit surface is evaluated on (``base``
        or its level-1 refinement, with the halves of ``base``'s crease edges).
    level : int, 0 if ``work`` is the base mesh, else 1.
    mesh : PolyMesh, the patch mesh: face ``i`` is patch ``i``, vertices are ``work``'s
        (unused ones included).
    face_of_patch : (k,) int64 base face of each patch.
    whole_quad : (k,) bool, the patch covers a whole base quad (always at level 0).
    work_face : (k,) int64 the ``work`` face a patch is (for ``whole_quad`` patches at
        level 1, the first of the base quad's four level-1 faces, in corner order).
    patch_corner : (k, 4) int64 index into ``mesh.face_vertices`` of each patch corner.
    corner_uv : (len(mesh.face_vertices), 2) float64 patch parameters of every corner.
    base_edge : (len(mesh.face_vertices),) int64 base edge a patch-mesh corner's edge
        lies on, -1 for edges inside a non-quad base face.
    """

    work: PolyMesh
    level: int
    mesh: PolyMesh
    face_of_patch: np.ndarray
    whole_quad: np.ndarray
    work_face: np.ndarray
    patch_corner: np.ndarray
    corner_uv: np.ndarray
    base_edge: np.ndarray

    @property
    def n_patches(self):
        return len(self.face_of_patch)


def build_patch_mesh(base):
    """The :class:`PatchMesh` of a closed polygon base mesh (see module docstring)."""
    sizes = base.face_sizes
    m, n = base.n_faces, len(base.vertices)
    fv = np.asarray(base.face_vertices, dtype=np.int64)
    fo = np.asarray(base.face_offsets, dtype=np.int64)
    topo = mesh_topology(fv, fo, n)
    if (sizes == 4).all():
        corners = np.arange(len(fv), dtype=np.int64)
        return PatchMesh(base, 0, base, np.arange(m, dtype=np.int64), np.ones(m, dtype=bool),
                         np.arange(m, dtype=np.int64), corners.reshape(m, 4),
                         CORNER_UV[corners % 4], topo.corner_edge.astype(np.int64))
    work, _ = subdivide(base)
    quad = sizes == 4
    face = topo.face_of_corner
    local = np.arange(len(fv)) - fo[face]
    edge = topo.corner_edge
    split = np.zeros(len(topo.edges), dtype=bool)
    split[edge[~quad[face]]] = True
    per_face = np.where(quad, 1, sizes)
    patch_start = np.concatenate([[0], np.cumsum(per_face)[:-1]])
    edge_point = n + m + edge
    prev_edge_point = n + m + edge[topo.prev_corner]

    # entries (patch, order key, vertex, u, v, patch-corner slot or -1, base edge of the side)
    q = np.flatnonzero(quad[face])
    qs = q[split[edge[q]]]
    r = np.flatnonzero(~quad[face])
    patch = np.concatenate([patch_start[face[q]], patch_start[face[qs]],
                            np.repeat(patch_start[face[r]] + local[r], 4)])
    order = np.concatenate([2 * local[q], 2 * local[qs] + 1, np.tile(np.arange(4), len(r))])
    vertex = np.concatenate([fv[q], edge_point[qs],
                             np.stack([fv[r], edge_point[r], n + face[r], prev_edge_point[r]],
                                      axis=1).reshape(-1)])
    uv = np.concatenate([CORNER_UV[local[q]], SIDE_MID_UV[local[qs]], np.tile(CORNER_UV, (len(r), 1))])
    slot = np.concatenate([local[q], np.full(len(qs), -1), np.tile(np.arange(4), len(r))])
    side_edge = np.concatenate([edge[q], edge[qs],
                                np.stack([edge[r], np.full(len(r), -1), np.full(len(r), -1),
                                          edge[topo.prev_corner[r]]], axis=1).reshape(-1)])
    sort = np.lexsort((order, patch))
    patch, vertex, uv, slot, side_edge = (a[sort] for a in (patch, vertex, uv, slot, side_edge))
    k = int(per_face.sum())
    offsets = np.concatenate([[0], np.cumsum(np.bincount(patch, minlength=k))]).astype(np.int64)
    mesh = PolyMesh(work.vertices, vertex.astype(np.int64), offsets)
    is_slot = slot >= 0
    patch_corner = np.empty((k, 4), dtype=np.int64)
    patch_corner[patch[is_slot], slot[is_slot]] = np.flatnonzero(is_slot)
    face_of_patch = np.repeat(np.arange(m, dtype=np.int64), per_face)
    whole_quad = quad[face_of_patch]
    work_face = np.where(whole_quad, fo[face_of_patch],
                         fo[face_of_patch] + np.arange(k) - patch_start[face_of_patch])
    return PatchMesh(work, 1, mesh, face_of_patch, whole_quad, work_face.astype(np.int64),
                     patch_corner, uv, side_edge.astype(np.int64))

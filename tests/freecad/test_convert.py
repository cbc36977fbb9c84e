# SPDX-License-Identifier: LGPL-2.1-or-later
"""The numpy <-> ``Mesh.Mesh`` bridge: the binary-file path gives exactly the mesh and the
arrays FreeCAD's own list-based constructor and ``Topology`` give."""
import os
import tempfile

import numpy as np

import FreeCAD
import Mesh

from polycube_wb import convert
from polycube_wb.mesh_binary import binary_mesh


def _sphere(levels=2):
    """A closed triangulated sphere (icosahedron split ``levels`` times), radius 10 mm."""
    t = (1.0 + 5 ** 0.5) / 2.0
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    V = [np.asarray(v, float) / np.linalg.norm(v) * 10.0 for v in V]
    for _ in range(levels):
        middle, faces = {}, []

        def split(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                point = V[a] + V[b]
                V.append(point / np.linalg.norm(point) * 10.0)
                middle[key] = len(V) - 1
            return middle[key]

        for a, b, c in F:
            ab, bc, ca = split(a, b), split(b, c), split(c, a)
            faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = faces
    return np.asarray(V), np.asarray(F, np.int64)


def _kernel_bytes(mesh):
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "mesh.bms")
        mesh.write(path)
        with open(path, "rb") as handle:
            return handle.read()


def _list_built(V, F):
    return Mesh.Mesh((convert.arrays_to_vectors(V), [tuple(f) for f in F.tolist()]))


def test_closed_mesh_is_built_as_freecad_builds_it():
    V, F = _sphere()
    V[0] = (-0.0, 0.0, 10.0)  # a signed zero
    mesh = convert.arrays_to_mesh(V, F)
    reference = _list_built(V, F)
    assert _kernel_bytes(mesh) == _kernel_bytes(reference), "points, facets and neighbours"
    assert mesh.isSolid() and not mesh.hasInvalidNeighbourhood()
    assert mesh.Topology == reference.Topology


def test_arrays_equal_topology_with_and_without_placement():
    V, F = _sphere()
    V[3] = (-0.0, 10.0, -0.0)
    mesh = convert.arrays_to_mesh(V, F)
    points, facets = mesh.Topology
    got_V, got_F = convert.mesh_to_arrays(mesh)
    assert got_V.tobytes() == convert.vectors_to_array(points).tobytes()  # +0.0 as Topology
    assert np.array_equal(got_F, np.asarray(facets)) and got_F.dtype == np.int64
    mesh.Placement = FreeCAD.Placement(FreeCAD.Vector(1, 2, 3), FreeCAD.Rotation(10, 20, 30))
    moved_V, _ = convert.mesh_to_arrays(mesh)
    assert moved_V.tobytes() == convert.vectors_to_array(mesh.Topology[0]).tobytes()


def test_open_and_non_manifold_meshes_take_freecads_builder():
    V, F = _sphere(1)
    open_F = F[1:]
    assert binary_mesh(V, open_F) is None
    assert convert.arrays_to_mesh(V, open_F).Topology == _list_built(V, open_F).Topology
    doubled = np.vstack([F, F[:1]])  # one triangle twice: its edges join three triangles
    assert binary_mesh(V, doubled) is None

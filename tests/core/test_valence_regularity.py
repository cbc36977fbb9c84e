# SPDX-License-Identifier: LGPL-2.1-or-later
"""Valence regularisation of quad cages (core.quadmesh.valence_regularity): edge rotations and
diagonal collapses take out extraordinary vertices made in a regular torus, keep the genus and
a valid closed cage, and never merge a fixed (crease) vertex."""
import numpy as np
import pytest

from core.mesh_topology import polymesh_genus
from core.polymesh_checks import check_polymesh
from core.quadmesh.valence_regularity import regularise_valences
from core.subdivision.sample_cages import torus
from core.types import PolyMesh

pytestmark = pytest.mark.unit

N_MAJOR, N_MINOR = 12, 8


def grid_index(i, j):
    """Vertex of the torus grid at major step ``i``, minor step ``j``."""
    return (i % N_MAJOR) * N_MINOR + (j % N_MINOR)


def regular_torus():
    """(vertices, faces as lists): a torus grid, every vertex of valence 4."""
    mesh = torus(N_MAJOR, N_MINOR, major_radius=4.0, minor_radius=1.5)
    return np.array(mesh.vertices), [list(map(int, face)) for face in mesh.faces()]


def as_mesh(vertices, faces):
    """PolyMesh of the used vertices, checked closed and 2-manifold."""
    used = np.unique(np.concatenate(faces))
    renumber = np.full(len(vertices), -1)
    renumber[used] = np.arange(len(used))
    mesh = PolyMesh.from_faces(np.asarray(vertices)[used], [renumber[f] for f in faces])
    check_polymesh(mesh)
    return mesh


def extraordinary(mesh):
    """Vertices of valence other than 4."""
    return int((np.bincount(mesh.face_vertices) != 4).sum())


def face_with(faces, *corners):
    """Index of the face holding all ``corners``."""
    return next(k for k, face in enumerate(faces) if set(corners) <= set(face))


def rotated_edge_torus():
    """The regular torus with one edge between two quads turned to another diagonal of their
    hexagon: four extraordinary vertices (two of valence 3, two of valence 5)."""
    V, faces = regular_torus()
    u, v = grid_index(3, 2), grid_index(3, 3)  # an edge along the minor direction
    first = face_with(faces, u, v, grid_index(4, 2))
    second = face_with(faces, u, v, grid_index(2, 2))
    one, two = faces[first], faces[second]
    k = one.index(u) if one[(one.index(u) + 1) % 4] == v else one.index(v)
    one = one[k:] + one[:k]
    a, b = one[0], one[1]
    k = two.index(b)
    two = two[k:] + two[:k]
    hexagon = [a, two[2], two[3], b, one[2], one[3]]
    faces[first] = [hexagon[1], hexagon[2], hexagon[3], hexagon[4]]
    faces[second] = [hexagon[4], hexagon[5], hexagon[0], hexagon[1]]
    return V, faces


def split_vertex_torus():
    """The regular torus with one vertex split in two along its minor-direction edges, a thin
    quad between the halves: valence 3 at the halves, 5 at the two vertices they share."""
    V, faces = regular_torus()
    i, j = 5, 4
    p = grid_index(i, j)
    east, north, west, south = (grid_index(i + 1, j), grid_index(i, j + 1),
                                grid_index(i - 1, j), grid_index(i, j - 1))
    half = len(V)
    V = np.vstack([V, V[p] + 0.25 * (V[west] - V[p])])
    V[p] = V[p] + 0.25 * (V[east] - V[p])
    for k, face in enumerate(faces):
        if p in face and (west in face):
            faces[k] = [half if w == p else w for w in face]
    faces.append([p, north, half, south])
    return V, faces


def test_regular_torus_is_left_as_it_is():
    V, faces = regular_torus()
    result = regularise_valences(V, faces)
    assert (result.rotations, result.collapses) == (0, 0)
    assert result.faces == faces


def test_a_turned_edge_is_turned_back():
    V, faces = rotated_edge_torus()
    before = as_mesh(V, faces)
    assert extraordinary(before) == 4
    result = regularise_valences(V, faces)
    after = as_mesh(result.vertices, result.faces)
    assert extraordinary(after) == 0
    assert len(result.faces) == len(faces)
    assert polymesh_genus(after) == polymesh_genus(before) == 1


def test_a_split_vertex_is_collapsed_back_onto_the_surface():
    V, faces = split_vertex_torus()
    before = as_mesh(V, faces)
    assert extraordinary(before) == 4
    result = regularise_valences(V, faces)
    after = as_mesh(result.vertices, result.faces)
    assert extraordinary(after) == 0
    assert len(result.faces) == len(faces) - 1
    assert polymesh_genus(after) == 1
    # the merged vertex is one of the two halves, not a new point
    moved = np.flatnonzero(np.any(result.vertices[:len(V)] != V, axis=1))
    for vertex in moved:
        assert np.any(np.all(result.vertices[vertex] == V, axis=1))


def test_fixed_vertices_are_never_merged():
    V, faces = split_vertex_torus()
    halves = {grid_index(5, 4), len(V) - 1}
    result = regularise_valences(V, faces, fixed_vertices=halves)
    used = set(np.concatenate(result.faces).tolist())
    assert halves <= used
    assert np.array_equal(result.vertices[list(halves)], V[list(halves)])


def test_no_edit_makes_a_folded_quad():
    V, faces = rotated_edge_torus()
    result = regularise_valences(V, faces)
    for face in result.faces:
        P = result.vertices[face]
        normal = np.cross(P[2] - P[0], P[3] - P[1])
        turns = np.cross(np.roll(P, -1, axis=0) - P, np.roll(P, 1, axis=0) - P) @ normal
        assert (turns > 0).all()

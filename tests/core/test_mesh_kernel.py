# SPDX-License-Identifier: LGPL-2.1-or-later
"""The mesh kernel (``core.geometry``, ``core.mesh_topology``) on meshes with known answers."""
import numpy as np
import pytest
import trimesh

from core.geometry import (face_areas, face_cross, polymesh_volume, triangle_mesh_volume,
                           triangle_signed_volumes, triangulate, unit_face_normals)
from core.mesh_topology import (edge_faces, euler_characteristic, face_neighbours, genus_of,
                                neighbour_mean, next_corners, previous_corners)
from core.subdivision.sample_cages import cube, genus3_block


def test_box_areas_normals_and_volumes_far_from_the_origin():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    V, F = np.asarray(box.vertices) + 1e6, np.asarray(box.faces)
    assert face_areas(V, F).sum() == pytest.approx(2 * (2 + 3 + 6), rel=1e-9)
    unit = face_cross(V, F) / (2 * face_areas(V, F))[:, None]
    assert np.allclose(unit, box.face_normals, atol=1e-9), "outward normals"
    assert triangle_mesh_volume(V, F) == pytest.approx(6.0, rel=1e-12)
    assert triangle_signed_volumes(V, F).sum() == pytest.approx(6.0, rel=1e-6)
    assert triangle_mesh_volume(V, F[:, ::-1]) == pytest.approx(-6.0, rel=1e-12)


@pytest.mark.parametrize("mesh, components, genus", [
    (trimesh.creation.icosphere(2), 1, 0),
    (trimesh.creation.torus(2.0, 0.5), 1, 1),
])
def test_euler_characteristic_and_genus(mesh, components, genus):
    F = np.asarray(mesh.faces)
    assert euler_characteristic(len(mesh.vertices), F) == 2 - 2 * genus
    assert genus_of(len(mesh.vertices), F, components) == genus


def test_next_corners_cycle_within_each_face():
    offsets = np.array([0, 4, 7, 12])
    following = next_corners(offsets)
    assert following.tolist() == [1, 2, 3, 0, 5, 6, 4, 8, 9, 10, 11, 7]
    assert previous_corners(offsets)[following].tolist() == list(range(12))
    assert next_corners(np.array([0])).tolist() == []


def test_neighbour_mean_of_a_closed_cage_counts_each_neighbour_once():
    """On the unit cube cage every corner has three neighbours, one step along each axis:
    their mean lies a third of the way towards the opposite corner."""
    c = cube()
    mean = neighbour_mean(c.vertices, c.face_vertices, c.face_offsets)
    expected = c.vertices + (1.0 - 2.0 * c.vertices) / 3.0
    np.testing.assert_allclose(mean, expected, atol=1e-15)


def test_unit_normals_are_outward_and_zero_on_a_degenerate_triangle():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    V, F = np.asarray(box.vertices), np.asarray(box.faces)
    assert np.allclose(unit_face_normals(V, F), box.face_normals, atol=1e-12)
    sliver = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert unit_face_normals(sliver, np.array([[0, 1, 2]])).tolist() == [[0.0, 0.0, 0.0]]


def test_fan_triangulation_keeps_orientation_and_gives_n_minus_2_triangles():
    # a quad, a triangle and a pentagon
    offsets = np.array([0, 4, 7, 12])
    corners = np.arange(12)
    T = triangulate(corners, offsets)
    assert T.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [7, 9, 10], [7, 10, 11]]


@pytest.mark.parametrize("cage, volume", [(cube(2.0), 8.0), (genus3_block(1.0), 7 * 3 * 1 - 3)])
def test_polygon_mesh_volume_of_closed_cages(cage, volume):
    V = cage.vertices + np.array([1e5, -2e5, 3e5])  # far from the origin
    assert polymesh_volume(V, cage.face_vertices, cage.face_offsets) == pytest.approx(volume,
                                                                                        rel=1e-9)
    reversed_faces = np.concatenate([f[::-1] for f in cage.faces()])
    assert polymesh_volume(V, reversed_faces, cage.face_offsets) == pytest.approx(-volume,
                                                                                   rel=1e-9)


@pytest.mark.parametrize("height", [0.0, 1e-16, 1e-14, 2e-14, 1e-13, 1e-12, 1e-6])
def test_intake_labeling_and_cage_check_agree_on_zero_area_faces(height):
    """One zero-area tolerance (``core.tolerances.ZERO_AREA``): a face the intake keeps is
    one the labeling can take the normal of, and the cage check agrees."""
    from core.errors import InvalidMeshError
    from core.polymesh_checks import check_polymesh
    from core.segmentation.labeling import face_normals
    from core.types import PolyMesh
    from core.validate import check_degenerate_faces

    # a unit-diagonal triangle fixes the diagonal; the sliver has twice-area = height
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                  [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, height, 0.0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])
    diagonal2 = 2.0
    zero = height <= 1e-14 * diagonal2

    def rejected(check):
        try:
            check()
        except InvalidMeshError as exc:
            return exc.reason == "degenerate_faces"
        return False

    assert rejected(lambda: check_degenerate_faces(V, F)) == zero
    assert rejected(lambda: face_normals(V, F)) == zero
    # the same face as a polygon of a cage (the cage is open: only the area verdict counts)
    cage = PolyMesh.from_faces(V, [[3, 4, 5], [0, 1, 2]])
    try:
        check_polymesh(cage)
    except InvalidMeshError as exc:
        assert (exc.reason == "degenerate_faces") == zero, exc


def test_face_neighbours_share_the_edge_and_point_back():
    mesh = trimesh.creation.torus(2.0, 0.5)
    F = np.asarray(mesh.faces, dtype=np.int64)
    across = face_neighbours(F)
    m = len(F)
    assert (across >= 0).all(), "closed mesh: every edge has a face on the other side"
    own = np.repeat(np.arange(m), 3)
    # the neighbour across edge k of f has f across one of its edges
    assert ((across[across.reshape(-1)] == own[:, None]).sum(axis=1) == 1).all()
    # and holds both ends of that edge
    a, b = F.reshape(-1), np.roll(F, -1, axis=1).reshape(-1)
    other = F[across.reshape(-1)]
    assert ((other == a[:, None]).any(axis=1) & (other == b[:, None]).any(axis=1)).all()
    edges, faces_of_edge = edge_faces(F)
    assert len(edges) == 3 * m // 2 and (faces_of_edge >= 0).all()
    # an open mesh: the removed face's neighbours see -1 there
    open_across = face_neighbours(F[1:])
    assert (open_across == -1).sum() == 3

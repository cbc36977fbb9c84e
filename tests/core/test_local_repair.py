# SPDX-License-Identifier: LGPL-2.1-or-later
"""Local edits of cages at inverted faces (core.quadmesh.local_repair): a corner folded over
its neighbours on a box, built here, and the paired cages of a thin-walled SIMP result
(``benchmarks/simp_unseen/simp_shelf_bracket.stl``) and of ``gripper_domain``."""
import os

import numpy as np
import pytest
import trimesh

from core.mesh_topology import polymesh_genus
from core.polymesh_checks import check_polymesh
from core.quadmesh.crossing_count import LimitCrossingCount
from core.quadmesh.local_repair import MAX_TRIANGLE_SHARE, repair_inverted
from core.quadmesh.orientation import inverted_faces
from core.quadmesh.decimation.paired_decimation import limit_flaws, paired_decimation_base_mesh
from core.subdivision.sample_cages import voxel_cage
from core.target_surface import TargetSurface
from core.types import PolyMesh
from dev_meshes import load_dev_mesh

SHELF_BRACKET = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "simp_unseen",
                             "simp_shelf_bracket.stl")


@pytest.fixture(scope="module")
def box():
    """A 6 x 6 x 2 box: its quad cage (unit faces, vertices on the box) and the box as target
    (the same quads split into triangles)."""
    cage = voxel_cage(np.ones((6, 6, 2), dtype=bool))
    quads = cage.face_vertices.reshape(-1, 4)
    target = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return cage, TargetSurface(cage.vertices, target)


def test_a_corner_folded_over_its_neighbours_goes_back_to_the_mean_of_them(box):
    cage, surface = box
    assert int(inverted_faces(cage, surface.vertices, surface.faces, surface).sum()) == 0
    top = int(np.flatnonzero(np.all(cage.vertices == [3.0, 3.0, 2.0], axis=1))[0])
    vertices = cage.vertices.copy()
    vertices[top] = [4.9, 4.9, 2.0]  # past its diagonal neighbour (4, 4, 2)
    folded = PolyMesh(vertices, cage.face_vertices, cage.face_offsets)
    count = LimitCrossingCount(folded)
    inverted = int(inverted_faces(folded, surface.vertices, surface.faces, surface).sum())
    assert inverted == 1 and count.crossings == 0
    repaired, crossings, left, edits = repair_inverted(folded, surface, count.crossings,
                                                       inverted, count)
    assert (crossings, left, edits) == (0, 0, 1)
    # the mean of its four neighbours on the grid is where it was (exact up to rounding)
    assert np.allclose(repaired.vertices, cage.vertices, rtol=0.0, atol=1e-12)
    assert np.array_equal(repaired.face_vertices, cage.face_vertices)


def test_a_limit_surface_crossing_itself_without_an_inverted_face_is_mended(box):
    cage, surface = box
    side = int(np.flatnonzero(np.all(cage.vertices == [0.0, 3.0, 1.0], axis=1))[0])
    vertices = cage.vertices.copy()
    vertices[side] = [0.3, 3.0, -1.4]  # a side-wall vertex pulled under the bottom
    folded = PolyMesh(vertices, cage.face_vertices, cage.face_offsets)
    count = LimitCrossingCount(folded)
    inverted = int(inverted_faces(folded, surface.vertices, surface.faces, surface).sum())
    assert inverted == 0 and count.crossings > 0
    repaired, crossings, left, edits = repair_inverted(folded, surface, count.crossings,
                                                       inverted, count)
    assert (crossings, left) == (0, 0) and 1 <= edits <= 2
    assert LimitCrossingCount(repaired).crossings == 0
    assert np.array_equal(repaired.face_vertices, cage.face_vertices)


def test_an_unflawed_cage_is_returned_as_it_is(box):
    cage, surface = box
    assert repair_inverted(cage, surface, 0, 0, LimitCrossingCount(cage)) == (cage, 0, 0, 0)


@pytest.mark.slow
def test_the_thin_shelf_bracket_gets_a_clean_cage_on_budget_with_split_quads():
    mesh = trimesh.load(SHELF_BRACKET, process=True)  # genus 7, walls two elements thick
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    surface = TargetSurface(vertices, faces)
    result = paired_decimation_base_mesh(vertices, faces, 300, surface, 375, 2500)
    # the last budget's cage is clean only after edits (some of them splits); without them
    # a larger budget's cage would be kept
    assert result.rounds[-1]["edits"] > 0
    assert limit_flaws(result.mesh, surface) == (0, 0)
    assert abs(result.mesh.n_faces - 300) <= 0.25 * 300
    assert 0 < result.triangles <= MAX_TRIANGLE_SHARE * result.mesh.n_faces
    check_polymesh(result.mesh)
    assert polymesh_genus(result.mesh) == 7


@pytest.mark.slow
def test_the_gripper_domain_cage_has_no_inverted_face():
    target = load_dev_mesh("gripper_domain.stl")  # genus 3, a 2 mm wall round a pin eye
    surface = TargetSurface(target.vertices, target.faces)
    result = paired_decimation_base_mesh(target.vertices, target.faces, 300, surface, 375, 2500)
    assert limit_flaws(result.mesh, surface) == (0, 0)
    assert abs(result.mesh.n_faces - 300) <= 0.25 * 300
    assert result.quads >= 0.9 * result.mesh.n_faces
    assert polymesh_genus(result.mesh) == 3


def test_two_corners_folded_together_are_untangled_in_the_tangent_plane(box):
    cage, surface = box
    vertices = cage.vertices.copy()
    moved = [int(np.flatnonzero(np.all(cage.vertices == corner, axis=1))[0])
             for corner in ([2.0, 2.0, 2.0], [3.0, 3.0, 2.0])]
    vertices[moved] = [[3.9, 3.9, 2.0], [4.9, 4.9, 2.0]]  # both past their neighbours on the top
    folded = PolyMesh(vertices, cage.face_vertices, cage.face_offsets)
    count = LimitCrossingCount(folded)
    inverted = int(inverted_faces(folded, surface.vertices, surface.faces, surface).sum())
    assert inverted > 0
    # one corner moved at a time does not unfold the pair
    assert repair_inverted(folded, surface, count.crossings, inverted, count)[2] > 0
    repaired, crossings, left, edits = repair_inverted(folded, surface, count.crossings,
                                                       inverted, count, untangle=True)
    assert (crossings, left) == (0, 0) and edits >= 1
    assert LimitCrossingCount(repaired).crossings == 0
    assert np.array_equal(repaired.face_vertices, cage.face_vertices)
    # the top's vertices moved in its plane, inside the top, no two of them together
    top = cage.vertices[:, 2] == 2.0
    assert np.allclose(repaired.vertices[top, 2], 2.0, rtol=0.0, atol=1e-9)
    assert np.all((repaired.vertices[top, :2] > -1e-9) & (repaired.vertices[top, :2] < 6 + 1e-9))
    assert np.allclose(repaired.vertices[~top], cage.vertices[~top], rtol=0.0, atol=1e-12)
    gaps = np.linalg.norm(repaired.vertices[top][:, None] - repaired.vertices[top][None], axis=2)
    assert gaps[~np.eye(int(top.sum()), dtype=bool)].min() > 0.1

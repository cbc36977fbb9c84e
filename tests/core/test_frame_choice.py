# SPDX-License-Identifier: LGPL-2.1-or-later
"""Per-part frame candidates (PCA, world axes, best normal-aligning rotation) and the choice by
labeling energy, on shapes built here and on a dev mesh."""
import manifold3d as m3
import numpy as np
import pytest
from dev_meshes import load_dev_mesh
from scipy.spatial.transform import Rotation

from core.segmentation.frame_choice import (CANDIDATES, best_aligned_frame, choose_part_frames,
                                            labeling_energy)
from core.segmentation.frames import CUBE_GROUP, compute_frames
from core.segmentation.part_frame import cubic_energy, group_moments, part_frames
from core.segmentation.labeling import face_normals, mean_label_angle, nearest_direction_labels
from core.types import TriMesh

def _mesh(manifold):
    out = manifold.to_mesh()
    return TriMesh(np.asarray(out.vert_properties[:, :3], dtype=np.float64),
                   np.asarray(out.tri_verts, dtype=np.int64))


def _l_shape(rotation=None):
    """An L of two 10 x 2 x 2 bars in the world grid, optionally rotated (scipy Rotation)."""
    leg = m3.Manifold.cube([10.0, 2.0, 2.0]) + m3.Manifold.cube([2.0, 10.0, 2.0])
    mesh = _mesh(leg.refine(3))
    if rotation is not None:
        mesh = TriMesh(mesh.vertices @ rotation.as_matrix().T, mesh.faces)
    return mesh


def _min_angle_to_cube_group(frame, reference):
    """Smallest rotation angle (degrees) between ``frame`` and ``reference`` up to the 24 axis
    permutations/signs (frames with the same six label directions)."""
    c = (np.einsum("gij,ij->g", CUBE_GROUP @ frame, reference) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c.max(), -1.0, 1.0))))


def _area_mean_angle(mesh, frame):
    m = len(mesh.faces)
    ff = np.broadcast_to(frame, (m, 3, 3))
    n = face_normals(mesh.vertices, mesh.faces)
    tri = mesh.vertices[mesh.faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return mean_label_angle(n, nearest_direction_labels(n, ff), ff, weights=area)


def test_l_shape_in_the_world_grid_keeps_the_world_axes():
    mesh = _l_shape()
    part = np.zeros(len(mesh.faces), dtype=np.int64)
    pca = part_frames(mesh.vertices, mesh.faces, part)
    # PCA of an L turns away from its bars (the symmetric L's axes lie along the diagonal)
    assert _min_angle_to_cube_group(pca[0], np.eye(3)) > 20.0
    choice = choose_part_frames(mesh.vertices, mesh.faces, part, pca)
    assert choice.source[0] in ("world", "aligned")
    assert _min_angle_to_cube_group(choice.frames[0], np.eye(3)) < 1e-6
    assert choice.energy[0, CANDIDATES.index("pca")] > choice.energy[0].min()
    # every face normal is along a label direction of the chosen frame (0 degrees)
    assert _area_mean_angle(mesh, choice.frames[0]) < 1e-6
    assert _area_mean_angle(mesh, pca[0]) > 20.0


def test_rotated_l_shape_gets_the_aligned_rotation():
    rot = Rotation.from_euler("zyx", [25, 10, -15], degrees=True)
    mesh = _l_shape(rot)
    part = np.zeros(len(mesh.faces), dtype=np.int64)
    choice = choose_part_frames(mesh.vertices, mesh.faces, part,
                                part_frames(mesh.vertices, mesh.faces, part))
    assert choice.source[0] == "aligned"
    # the bars' directions are the rows of the rotation's matrix transposed
    assert _min_angle_to_cube_group(choice.frames[0], rot.as_matrix().T) < 1e-3
    frame = choice.frames[0]
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-10)
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-10)


def test_best_aligned_frame_lowers_the_cubic_energy_to_zero_on_a_box():
    rot = Rotation.from_euler("xyz", [30, 20, 40], degrees=True)
    box = _mesh(m3.Manifold.cube([3.0, 2.0, 1.0]).refine(2))
    V = box.vertices @ rot.as_matrix().T
    n4 = group_moments(V, box.faces, np.zeros(len(box.faces), dtype=np.int64), 1)[0].normal4
    area = float(np.trace(n4.reshape(9, 9)))
    start = np.eye(3)
    assert cubic_energy(n4, start) > 0.05 * area
    frame = best_aligned_frame(n4, start)
    assert cubic_energy(n4, frame) < 1e-9 * area


def test_labeling_energy_counts_cut_edges_and_normal_cost():
    # two faces of one part, normals +X and +Y, sharing an edge: cost 0 each, one cut edge
    normals = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    part = np.array([0, 0, 1])
    pairs = np.array([[0, 1]])
    e = labeling_energy(normals, pairs, part, np.stack([np.eye(3)] * 2), lam=0.5)
    assert e == pytest.approx([0.5, 0.0])
    # rotated 30 degrees about z: both faces cost 2 - 2 cos 30 and keep different labels
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    frames = np.stack([rot, np.eye(3)])
    e = labeling_energy(normals, pairs, part, frames, lam=0.5)
    assert e == pytest.approx([2 * (2 - 2 * c) + 0.5, 0.0])
    # lambda weighs the cut edges only
    e0 = labeling_energy(normals, pairs, part, frames, lam=0.0)
    assert e0 == pytest.approx([2 * (2 - 2 * c), 0.0])


def test_compute_frames_reports_the_choice_per_part_and_pca_mode_keeps_pca():
    mesh = _l_shape()
    part = (mesh.vertices[mesh.faces].mean(axis=1)[:, 1] > 6.0).astype(np.int64)
    field = compute_frames(mesh, part)
    assert len(field.part_frame_source) == 2
    assert set(field.part_frame_source) <= set(CANDIDATES)
    assert field.part_frame_energy.shape == (2, 3)
    pick = [CANDIDATES.index(s) for s in field.part_frame_source]
    assert np.allclose(field.part_frame_energy[[0, 1], pick], field.part_frame_energy.min(axis=1))
    pca = compute_frames(mesh, part, choose="pca")
    assert pca.part_frame_source == ("pca", "pca")
    assert np.array_equal(pca.part_frames, part_frames(mesh.vertices, mesh.faces, part))


@pytest.mark.parametrize("name", ["to_simp_lbracket.stl", "ge_bracket_domain.stl"])
def test_dev_mesh_frame_is_no_worse_than_world_or_pca(name):
    """On TO results the chosen frame's nearest-direction angle is at most that of the better of
    the world axes and PCA (PCA alone is clearly worse on the L-bracket)."""
    mesh = load_dev_mesh(name)
    part = np.zeros(len(mesh.faces), dtype=np.int64)
    pca = part_frames(mesh.vertices, mesh.faces, part)
    choice = choose_part_frames(mesh.vertices, mesh.faces, part, pca)
    best = min(_area_mean_angle(mesh, np.eye(3)), _area_mean_angle(mesh, pca[0]))
    assert _area_mean_angle(mesh, choice.frames[0]) <= best + 1.0

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Mesh intake: reading and validation, on real meshes and on bad meshes built here."""
import hashlib
import os
import struct

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError, ParameterError
from core.mesh_io import read_triangle_soup
from core.self_intersection import box_pairs, face_boxes, find_self_intersections
from core.validate import validate_target

MESHES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "meshes")


def box(center=(0, 0, 0), size=1.0):
    mesh = trimesh.creation.box(extents=(size, size, size))
    return np.asarray(mesh.vertices) + np.asarray(center, dtype=float), np.asarray(mesh.faces)


def write_stl(path, V, F):
    trimesh.Trimesh(V, F, process=False).export(path)
    return str(path)


def reason_of(V, F, **kwargs):
    with pytest.raises(InvalidMeshError) as info:
        validate_target(V, F, **kwargs)
    return info.value


def test_box_is_accepted_with_its_figures():
    V, F = box(size=2.0)
    mesh, summary = validate_target(V, F)
    assert summary["triangles"] == 12 and summary["vertices"] == 8
    assert summary["genus"] == 0 and summary["components"] == 1
    assert summary["volume"] == pytest.approx(8.0)
    assert summary["bbox_diagonal"] == pytest.approx(2.0 * np.sqrt(3.0))
    assert summary["warnings"] == []


@pytest.mark.parametrize("name, genus", [("to_simp_lbracket.stl", 8), ("polycube_bone.obj", 0),
                                         ("tray_bottom.stl", 23)])
def test_dev_meshes_are_accepted(name, genus):
    V, F = read_triangle_soup(os.path.join(MESHES, name))
    mesh, summary = validate_target(V, F, name=name)
    assert summary["genus"] == genus and summary["components"] == 1
    assert summary["volume"] > 0
    assert trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).is_watertight


def test_open_mesh_is_rejected_with_a_location():
    V, F = box()
    error = reason_of(V, F[:-1])
    assert error.reason == "open" and error.count == 3
    assert "3 boundary edges" in str(error) and "face" in str(error) and "at (" in str(error)


def test_non_manifold_edge_is_rejected():
    V, F = box()
    # a closed tetrahedron hinged on one edge of the box: that edge has four faces
    a, b = F[0][0], F[0][1]
    t1, t2 = len(V), len(V) + 1
    away = (V[a] + V[b]) / 2 * 3.0
    V2 = np.vstack([V, [away + [0.3, 0, 0], away + [0, 0.3, 0.2]]])
    F2 = np.vstack([F, [[a, b, t1], [a, t2, b], [a, t1, t2], [b, t2, t1]]])
    error = reason_of(V2, F2)
    assert error.reason == "non_manifold" and "non-manifold edges" in str(error)


def test_non_manifold_vertex_is_rejected():
    V1, F1 = box(center=(0, 0, 0))
    V2, F2 = box(center=(1, 1, 1))  # touches the first box at the corner (0.5, 0.5, 0.5)
    error = reason_of(np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)]))
    assert error.reason == "non_manifold" and "non-manifold vertices" in str(error)
    assert "(0.5, 0.5, 0.5)" in str(error)


def test_flipped_face_is_fixed_and_reported():
    V, F = box()
    F = F.copy()
    F[3] = F[3][::-1]
    mesh, summary = validate_target(V, F)
    assert summary["reoriented_faces"] == 1
    assert "re-oriented 1 faces" in summary["warnings"][0]
    assert trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).is_winding_consistent
    assert summary["volume"] == pytest.approx(1.0)


def test_inside_out_mesh_is_flipped_outwards():
    V, F = box()
    mesh, summary = validate_target(V, F[:, ::-1])
    assert summary["volume"] == pytest.approx(1.0) and summary["reoriented_faces"] == 12


def test_nan_vertex_is_rejected():
    V, F = box()
    V = V.copy()
    V[5, 1] = np.nan
    error = reason_of(V, F)
    assert error.reason == "non_finite" and "vertex 5" in str(error)


def test_zero_area_faces_are_rejected_without_repair():
    V, F = box()
    V2 = np.vstack([V, V[F[0, 0]] * 0.5 + V[F[0, 1]] * 0.5])
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
    error = reason_of(V2, F2, repair=False)
    assert error.reason == "degenerate_faces" and "1 degenerate" in str(error)
    assert reason_of(V2, F2).reason == "open"  # a zero-area fin is no repairable defect


def test_duplicate_faces_are_rejected_without_repair():
    V, F = box()
    error = reason_of(V, np.vstack([F, F[4:5]]), repair=False)
    assert error.reason == "duplicate_faces" and "face 12" in str(error)


def test_self_intersecting_pair_is_rejected():
    V, F = box()
    V = V.copy()
    # push one corner through the opposite face: its faces now cross that face
    corner = int(np.argmax(V.sum(axis=1)))
    V[corner] = [-0.9, 0.3, 0.2]
    error = reason_of(V, F)
    assert error.reason == "self_intersecting" and error.count >= 1
    assert "pairs of intersecting faces" in str(error)


def test_two_touching_faces_are_not_self_intersections():
    """Two boxes face to face (shared plane x = 0.5, no shared vertices) only touch;
    pushed 1e-3 into each other, the same boxes intersect."""
    V1, F1 = box(center=(0, 0, 0))
    for shift, touching in ((0.0, True), (-1e-3, False)):
        V2, F2 = box(center=(1.0 + shift, 0.5, 0.25))
        V, F = np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)])
        assert len(box_pairs(*face_boxes(V[F]))) > 100, "the narrow phase sees the contact"
        if touching:
            assert len(find_self_intersections(V, F)) == 0
            mesh, summary = validate_target(V, F, components="all")
            assert summary["components"] == 2 and summary["genus"] == 0
            assert summary["volume"] == pytest.approx(2.0, abs=1e-12)
        else:
            assert len(find_self_intersections(V, F)) > 0
            assert reason_of(V, F, components="all").reason == "self_intersecting"


def test_components_policy():
    V1, F1 = box(center=(0, 0, 0), size=2.0)
    V2, F2 = box(center=(5, 0, 0))
    V, F = np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)])
    mesh, summary = validate_target(V, F, components="largest")
    assert summary["volume"] == pytest.approx(8.0) and summary["components"] == 2
    assert "kept the largest of 2 components" in summary["warnings"][0]
    mesh, summary = validate_target(V, F, components="all")
    assert summary["volume"] == pytest.approx(9.0)
    error = reason_of(V, F, components="error")
    assert error.reason == "multiple_components" and "2 separate components" in str(error)
    with pytest.raises(ParameterError):
        validate_target(V, F, components="some")


def test_overlapping_components_are_self_intersecting():
    V1, F1 = box(center=(0, 0, 0))
    V2, F2 = box(center=(0.5, 0.3, 0.2))
    error = reason_of(np.vstack([V1, V2]), np.vstack([F1, F2 + len(V1)]), components="all")
    assert error.reason == "self_intersecting"


def test_empty_file(tmp_path):
    path = tmp_path / "empty.stl"
    path.write_bytes(b"")
    with pytest.raises(InvalidMeshError) as info:
        read_triangle_soup(path)
    assert info.value.reason == "empty" and "empty" in str(info.value)


def test_truncated_binary_stl(tmp_path):
    V, F = box()
    path = write_stl(tmp_path / "box.stl", V, F)
    data = open(path, "rb").read()
    assert struct.unpack("<I", data[80:84])[0] == 12
    (tmp_path / "cut.stl").write_bytes(data[:-30])
    with pytest.raises(InvalidMeshError) as info:
        read_triangle_soup(tmp_path / "cut.stl")
    assert info.value.reason == "unreadable" and "truncated" in str(info.value)


def test_wrong_extension_and_garbage(tmp_path):
    path = tmp_path / "mesh.xyz"
    path.write_text("1 2 3\n")
    with pytest.raises(InvalidMeshError) as info:
        read_triangle_soup(path)
    assert info.value.reason == "format" and ".xyz" in str(info.value)
    garbage = tmp_path / "garbage.obj"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(InvalidMeshError) as info:
        read_triangle_soup(garbage)
    assert info.value.reason in ("empty", "unreadable")


def test_missing_file(tmp_path):
    with pytest.raises(InvalidMeshError) as info:
        read_triangle_soup(tmp_path / "nope.stl")
    assert "no such file" in str(info.value)


@pytest.mark.parametrize("suffix", ["stl", "obj", "ply", "off"])
def test_every_format_reads_the_same_box(tmp_path, suffix):
    V, F = box()
    path = tmp_path / f"box.{suffix}"
    trimesh.Trimesh(V, F, process=False).export(path)
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    mesh, summary = validate_target(*read_triangle_soup(path))
    assert summary["triangles"] == 12 and summary["volume"] == pytest.approx(1.0)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before


def test_validation_is_deterministic():
    V, F = read_triangle_soup(os.path.join(MESHES, "to_simp_cantilever.stl"))
    a, _ = validate_target(V, F)
    b, _ = validate_target(V, F)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh validation and polygon OBJ input/output."""
import numpy as np
import pytest

from core.errors import InvalidMeshError, ParameterError
from core.polymesh_checks import check_export_range, check_polymesh
from core.polymesh_io import parse_obj, read_polymesh, write_polymesh
from core.subdivision import sample_cages as sc
from core.types import PolyMesh


@pytest.mark.parametrize("name", ["cube", "torus", "mixed_prism", "pentagonal_prism",
                                  "genus3_block", "grid_sphere"])
def test_good_cages_pass(name):
    check_polymesh(getattr(sc, name)())


def _cube_with(faces=None, vertices=None):
    c = sc.cube()
    return PolyMesh.from_faces(c.vertices if vertices is None else vertices,
                               c.faces() if faces is None else faces)


def _two_cubes(offset):
    c = sc.cube()
    V = np.vstack([c.vertices, c.vertices + offset])
    faces = c.faces() + [f + 8 for f in c.faces()]
    return PolyMesh.from_faces(V, faces)


def _bad_meshes():
    c = sc.cube()
    faces = c.faces()
    flipped_one = [f[::-1] if i == 0 else f for i, f in enumerate(faces)]
    inward = [f[::-1] for f in faces]
    collapsed = c.vertices.copy()
    collapsed[[1, 2, 3]] = collapsed[0]
    nan = c.vertices.copy()
    nan[4, 1] = np.nan
    # two cubes sharing an edge (4 faces on it), and two sharing only a vertex
    shared_edge = _two_cubes([1.0, 1.0, 0.0])
    se_v = shared_edge.vertices
    se_faces = [np.array([int(np.flatnonzero((se_v[:8] == se_v[i]).all(1))[0])
                          if i >= 8 and (se_v[:8] == se_v[i]).all(1).any() else i for i in f])
                for f in shared_edge.faces()]
    shared_vertex = _two_cubes([1.0, 1.0, 1.0])
    sv_v = shared_vertex.vertices
    sv_faces = [np.array([6 if i == 8 else i for i in f]) for f in shared_vertex.faces()]
    return {
        "open": _cube_with(faces=faces[1:]),
        "orientation": _cube_with(faces=flipped_one),
        "inward": _cube_with(faces=inward),
        "repeated_corner": _cube_with(faces=faces[:-1] + [np.array([3, 0, 0, 7])]),
        "two_corners": PolyMesh.from_faces(c.vertices, faces + [np.array([0, 1])]),
        "zero_area": _cube_with(vertices=collapsed),
        "non_finite": _cube_with(vertices=nan),
        "non_manifold_edge": PolyMesh.from_faces(se_v, se_faces),
        "non_manifold_vertex": PolyMesh.from_faces(sv_v, sv_faces),
        "out_of_range": _cube_with(faces=faces[:-1] + [np.array([3, 0, 4, 99])]),
        "empty": PolyMesh(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(1, np.int64)),
    }


EXPECTED = {
    "open": "open", "orientation": "orientation", "inward": "orientation",
    "repeated_corner": "degenerate_faces", "two_corners": "degenerate_faces",
    "zero_area": "degenerate_faces", "non_finite": "non_finite",
    "non_manifold_edge": "non_manifold", "non_manifold_vertex": "non_manifold",
    "out_of_range": "format", "empty": "empty",
}


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_bad_mesh_reasons(kind):
    with pytest.raises(InvalidMeshError) as err:
        check_polymesh(_bad_meshes()[kind])
    assert err.value.reason == EXPECTED[kind]
    if kind != "empty":
        assert err.value.count >= 1 and len(err.value.examples) >= 1
        assert str(err.value.count) in str(err.value)


def test_obj_round_trip_keeps_ngons(tmp_path):
    mesh = sc.pentagonal_prism()
    mesh = PolyMesh(mesh.vertices + np.pi * 1e-3, mesh.face_vertices, mesh.face_offsets)
    path = tmp_path / "prism.obj"
    write_polymesh(path, mesh)
    back = read_polymesh(path)
    assert np.array_equal(back.vertices, mesh.vertices)
    assert np.array_equal(back.face_vertices, mesh.face_vertices)
    assert np.array_equal(back.face_offsets, mesh.face_offsets)
    assert sorted(back.face_sizes.tolist()) == [4] * 5 + [5, 5]


def _creased_cube():
    """The unit cube with the four edges of its bottom face (vertices 0-3) tagged sharp."""
    cube = sc.cube()
    return PolyMesh(cube.vertices, cube.face_vertices, cube.face_offsets,
                    np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64))


def test_obj_round_trip_keeps_creases_as_opensubdiv_tags(tmp_path):
    """Crease edges survive an OBJ round trip as OpenSubdiv's ``t crease 2/1 a b 10`` tags
    (0-based indices), and the limit surface read back is the creased one, not the smooth."""
    from core.subdivision.limit import limit_volume

    mesh = _creased_cube()
    path = tmp_path / "creased.obj"
    write_polymesh(path, mesh)
    text = path.read_text()
    assert text.count("t crease 2/1 ") == 4 and "t crease 2/1 0 1 10" in text
    back = read_polymesh(path)
    check_polymesh(back)
    assert np.array_equal(back.creases, mesh.creases)
    smooth = limit_volume(sc.cube())
    creased = limit_volume(back)
    assert creased == pytest.approx(limit_volume(mesh), rel=1e-12)
    assert creased > smooth * 1.05, "a sharp bottom keeps more of the cube than a smooth one"
    # a cage without creases writes no tags and reads back without them
    write_polymesh(path, sc.cube())
    assert "t " not in path.read_text() and read_polymesh(path).creases is None


@pytest.mark.parametrize("tag, match", [
    ("t crease 2/1 0 1 2.5", "semi-sharp creases are not supported"),
    ("t corner 1/1 0 10", "only 't crease'"),
    ("t crease 2/1 0 10", "two 0-based vertex indices"),
    ("t crease 2/1 0 8 10", "outside 0..7"),
])
def test_obj_bad_crease_tags_are_refused(tag, match):
    text = "\n".join(["v %g %g %g" % tuple(p) for p in sc.cube().vertices]
                     + ["f " + " ".join(str(i + 1) for i in f) for f in sc.cube().faces()]
                     + [tag]) + "\n"
    with pytest.raises(InvalidMeshError, match=match) as err:
        parse_obj(text)
    assert err.value.reason == "format"


def test_crease_tag_on_a_face_diagonal_is_not_an_edge():
    cube = sc.cube()
    diagonal = PolyMesh(cube.vertices, cube.face_vertices, cube.face_offsets,
                        np.array([[0, 1], [0, 2]], dtype=np.int64))
    with pytest.raises(InvalidMeshError, match="not edges") as err:
        check_polymesh(diagonal)
    assert err.value.reason == "crease_not_edge" and err.value.examples == [[0, 2]]
    check_polymesh(_creased_cube())


def test_obj_write_protects_inputs_and_is_atomic(tmp_path):
    """The writer refuses to overwrite an input (even through another name), leaving
    it unchanged and no temporary file behind; an overwrite replaces the file whole."""
    path = tmp_path / "cage.obj"
    write_polymesh(path, sc.cube())
    before = path.read_bytes()
    alias = tmp_path / "alias.obj"
    alias.symlink_to(path)
    with pytest.raises(ParameterError, match="refusing to overwrite the input file"):
        write_polymesh(alias, sc.torus(), inputs=(path,))
    assert path.read_bytes() == before
    write_polymesh(path, sc.torus())
    assert read_polymesh(path).n_faces == sc.torus().n_faces
    assert sorted(p.name for p in tmp_path.iterdir()) == ["alias.obj", "cage.obj"]
    with pytest.raises(ParameterError, match="does not exist"):
        write_polymesh(tmp_path / "missing" / "x.obj", sc.cube())


@pytest.mark.parametrize("scale, shift, match", [(1.0, 1e15, "reach 1e\\+15 mm"),
                                                 (1e-5, 0.0, "too small")])
def test_export_range_is_checked(scale, shift, match):
    cube = sc.cube()
    mesh = PolyMesh(cube.vertices * scale + shift, cube.face_vertices, cube.face_offsets)
    with pytest.raises(InvalidMeshError, match=match) as err:
        check_export_range(mesh)
    assert err.value.reason == "coordinate_range"
    check_export_range(PolyMesh(cube.vertices * 1e4 - 5e6, cube.face_vertices, cube.face_offsets))


def test_obj_slash_forms_and_negative_indices():
    text = """# a tetrahedron written four ways
o tet
v 0 0 0
v 1 0 0
v 0 1 0
vt 0 0
vn 0 0 1
v 0 0 1
f 1/1/1 3/1/1 2/1/1
f 1//1 2//1 4//1
f 2/1 3/1 4/1
f -4 -1 -2
"""
    mesh = parse_obj(text)
    assert mesh.n_faces == 4 and len(mesh.vertices) == 4
    assert mesh.faces()[3].tolist() == [0, 3, 2]
    check_polymesh(mesh)


@pytest.mark.parametrize("text, reason", [
    ("v 0 0 0\nv 1 0 x\n", "format"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "format"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "format"),
    ("v 0 0 0\nv 1 0 0\n", "empty"),
    ("hello world\n", "empty"),
])
def test_obj_garbage(text, reason):
    with pytest.raises(InvalidMeshError) as err:
        parse_obj(text)
    assert err.value.reason == reason


def test_unreadable_files(tmp_path):
    with pytest.raises(InvalidMeshError) as err:
        read_polymesh(tmp_path / "missing.obj")
    assert err.value.reason == "unreadable"
    binary = tmp_path / "bin.obj"
    binary.write_bytes(bytes(range(256)))
    with pytest.raises(InvalidMeshError) as err:
        read_polymesh(binary)
    assert err.value.reason == "unreadable"

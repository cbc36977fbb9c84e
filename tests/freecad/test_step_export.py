# SPDX-License-Identifier: LGPL-2.1-or-later
"""Mixed cages to STEP: shared-edge solids, AP214 in millimetres, read back by two readers."""
import pytest

import FreeCAD  # noqa: F401  (must precede Part)
import Part

from core.polymesh_io import write_polymesh
from core.subdivision import sample_cages

# patches expected per cage (one per quad, n per n-gon) and the bound on the largest patch
# deviation from the exact limit surface (fraction of the bbox diagonal)
CAGES = {"mixed_prism": (7 + 3 * 10, 6.4e-5), "pentagonal_prism": (5 + 2 * 5, 3.1e-5),
         "genus3_block": (68, 1.6e-5), "cube": (6, 3.8e-6)}
NORMAL_JUMP_MAX_DEG = 0.315


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from polycube_wb.api import subd_to_solid

    folder = tmp_path_factory.mktemp("step")
    out = {}
    for name in CAGES:
        cage = folder / f"{name}.obj"
        write_polymesh(cage, getattr(sample_cages, name)())
        step = folder / f"{name}.step"
        solid, report = subd_to_solid(cage, step)
        out[name] = (solid, report, step)
    return out


@pytest.mark.parametrize("name", list(CAGES))
def test_one_face_per_quad_built_from_shared_edges(exported, name):
    solid, report, _ = exported[name]
    faces, max_error = CAGES[name]
    brep = report["brep"]
    assert brep["construction"] == "shared_edges" and brep["construction_note"] == ""
    assert brep["valid"] and brep["closed"] and brep["faces"] == faces == len(solid.Faces)
    assert solid.isValid() and len(solid.Shells) == 1 and solid.Shells[0].isClosed()
    assert abs(solid.Volume - brep["volume"]) <= 1e-7 * brep["volume"]
    assert brep["volume_error_rel"] < 1e-5
    assert report["patches"]["max_ev_error_rel"] <= max_error
    assert report["patches"]["normal_jump_max_deg"] <= NORMAL_JUMP_MAX_DEG


@pytest.mark.parametrize("name", ["mixed_prism", "genus3_block"])
def test_step_file_is_ap214_in_millimetres_with_the_input_name(exported, name):
    _, _, step = exported[name]
    text = step.read_text()
    assert "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));" in text
    assert "SI_UNIT(.MILLI.,.METRE.)" in text
    assert f"PRODUCT('{name}','{name}'," in text
    assert text.count("ADVANCED_FACE(") == CAGES[name][0]
    assert text.count("MANIFOLD_SOLID_BREP(") == 1 and text.count("CLOSED_SHELL(") == 1


@pytest.mark.parametrize("name", ["mixed_prism", "genus3_block"])
def test_every_edge_carries_its_parameter_lines_on_both_faces(exported, name):
    """Each EDGE_CURVE lies on a SURFACE_CURVE with two PCURVEs (one per face), and the
    solid read back has a parameter curve of every edge on each of its faces."""
    solid, _, step = exported[name]
    text = step.read_text()
    n_edges = text.count("EDGE_CURVE(")
    assert text.count("SURFACE_CURVE(") == n_edges == len(solid.Edges)
    assert text.count("PCURVE(") == 2 * n_edges
    for face in solid.Faces:
        for edge in face.Edges:
            assert face.curveOnSurface(edge)


@pytest.mark.parametrize("name", ["mixed_prism", "genus3_block"])
def test_each_point_is_written_once(exported, name):
    """Vertices, edge curves and neighbouring patches share their equal poles' entities."""
    import re

    _, _, step = exported[name]
    points = re.findall(r"CARTESIAN_POINT\('',\(([^)]*)\)\)", step.read_text())
    assert len(points) == len(set(points))
    edge_poles = sum(len(e.Curve.getPoles()) for e in exported[name][0].Edges)
    assert len(points) < edge_poles + sum(
        len(f.Surface.getPoles()) * len(f.Surface.getPoles()[0]) for f in exported[name][0].Faces)


def test_freecad_reads_back_the_same_solid(exported):
    solid, report, step = exported["mixed_prism"]
    shape = Part.read(str(step))
    assert shape.ShapeType == "Solid" and shape.isValid()
    assert len(shape.Faces) == len(solid.Faces) and len(shape.Edges) == len(solid.Edges)
    assert abs(shape.Volume - solid.Volume) <= 1e-9 * solid.Volume


def test_writing_twice_gives_identical_files(exported, tmp_path):
    from polycube_wb.api import subd_to_solid

    _, _, step = exported["mixed_prism"]
    cage = tmp_path / "mixed_prism.obj"
    write_polymesh(cage, sample_cages.mixed_prism())
    subd_to_solid(cage, tmp_path / "again.step", measure=False)
    again = (tmp_path / "again.step").read_text().replace("'again'", "'mixed_prism'")
    assert again == step.read_text()


def test_second_reader_gmsh_finds_one_closed_volume_in_millimetres(exported):
    """gmsh reads the STEP with its own OpenCascade build and meshes its surface."""
    gmsh = pytest.importorskip("gmsh")
    import numpy as np
    import trimesh

    solid, report, step = exported["mixed_prism"]
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        volumes = {}
        for unit in ("MM", "M"):
            gmsh.clear()
            gmsh.option.setString("Geometry.OCCTargetUnit", unit)
            gmsh.model.occ.importShapes(str(step))
            gmsh.model.occ.synchronize()
            entities = gmsh.model.getEntities(3)
            assert len(entities) == 1
            volumes[unit] = gmsh.model.occ.getMass(3, entities[0][1])
        assert len(gmsh.model.getBoundary(entities, oriented=False)) == CAGES["mixed_prism"][0]
        assert gmsh.model.getEntityName(3, entities[0][1]).endswith("mixed_prism")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.2e-3)
        gmsh.model.mesh.generate(2)
        nodes, coords, _ = gmsh.model.mesh.getNodes()
        _, _, connectivity = gmsh.model.mesh.getElements(2)
    finally:
        gmsh.finalize()
    assert abs(volumes["MM"] - solid.Volume) <= 1e-6 * solid.Volume
    assert abs(volumes["M"] - 1e-9 * solid.Volume) <= 1e-6 * 1e-9 * solid.Volume
    index = np.searchsorted(np.sort(nodes), np.concatenate(connectivity))
    order = np.argsort(nodes)
    surface = trimesh.Trimesh(coords.reshape(-1, 3)[order], index.reshape(-1, 3), process=True)
    assert surface.is_watertight
    assert abs(abs(surface.volume) - 1e-9 * solid.Volume) < 0.02 * 1e-9 * solid.Volume


def test_the_step_text_made_ahead_is_the_one_made_here(tmp_path):
    """The STEP text made on another core while the solid is built (``step_text_ahead``)
    writes the same file as the text made after it; one made for another product name is
    not used, and the file is still the same."""
    from core.export.bspline import limit_surface_patches
    from polycube_wb.brep import make_solid
    from polycube_wb.step_io import step_text_ahead, write_solid_step

    patches = limit_surface_patches(sample_cages.genus3_block(), measure=False)
    built = make_solid(patches)
    texts = []
    for label, ahead in (("here", None), ("ahead", step_text_ahead(patches, "block")),
                         ("renamed", step_text_ahead(patches, "another name"))):
        write_solid_step(built, patches, tmp_path / f"{label}.step", name="block", ahead=ahead)
        texts.append((tmp_path / f"{label}.step").read_text())
    assert "'block'" in texts[0] and texts[1] == texts[0] and texts[2] == texts[0]


def _largest_normal_jump_deg(shape, samples=5):
    """Largest angle (degrees) between the normals of the two faces of any edge of ``shape``,
    at ``samples`` points inside each edge."""
    import numpy as np

    faces_of = {}
    for face in shape.Faces:
        for edge in face.Edges:
            faces_of.setdefault(edge.hashCode(), (edge, []))[1].append(face)
    largest = 0.0
    for edge, faces in faces_of.values():
        first, last = edge.ParameterRange
        for t in np.linspace(first, last, samples + 2)[1:-1]:
            point = edge.valueAt(float(t))
            normals = [np.array(f.normalAt(*f.Surface.parameter(point))) for f in faces]
            cosine = np.clip(np.dot(normals[0], normals[1]), -1.0, 1.0)
            largest = max(largest, float(np.degrees(np.arccos(cosine))))
    return largest


@pytest.mark.slow
@pytest.mark.parametrize("faces", ["quad", "chart"])
def test_light_file_rounds_points_without_gaps_or_kinks(tmp_path, faces):
    """The light form of the G1 export (fewer decimals where they cannot open a gap) reads
    back as the same valid solid with the B-rep tolerance everywhere (a rounded boundary pole
    that a face did not share with its edge would open a gap of the rounding step, a hundred
    times the tolerance on this cage), its normals still agree across edges within the bound
    of the rounding, and it is shorter."""
    import dataclasses

    import numpy as np

    from core.export.g1_patches import g1_surface_patches
    from core.export.step_file import LIGHT_NORMAL_TURN, light_point_decimals, step_text
    from core.tolerances import BREP_MM
    from polycube_wb.brep import make_solid

    cage = sample_cages.mixed_prism()
    cage = dataclasses.replace(cage, vertices=100.0 * cage.vertices)
    patches = g1_surface_patches(cage, measure=False, faces=faces)
    built = make_solid(patches)
    assert 10.0 ** -light_point_decimals(patches.patches, built.topology).places.min() \
        > 100 * BREP_MM
    shapes, sizes = {}, {}
    for light in (False, True):
        text = step_text(patches.patches, built.topology, "prism", BREP_MM, built.reverse,
                         light=light)
        path = tmp_path / f"light_{light}.step"
        path.write_text(text)
        shapes[light], sizes[light] = Part.read(str(path)), len(text)
    light = shapes[True]
    assert light.ShapeType == "Solid" and light.isValid() and light.Shells[0].isClosed()
    assert len(light.Faces) == len(shapes[False].Faces) == len(patches.patches)
    tolerance = max(max(e.Tolerance for e in s.Edges + s.Vertexes) for s in shapes.values())
    assert tolerance <= 10 * BREP_MM
    assert abs(light.Volume - shapes[False].Volume) <= 1e-5 * shapes[False].Volume
    assert _largest_normal_jump_deg(shapes[False]) < 1e-3
    assert _largest_normal_jump_deg(light) <= 1.5 * 2 * np.degrees(LIGHT_NORMAL_TURN)
    assert sizes[True] < 0.97 * sizes[False]

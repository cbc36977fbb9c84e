# SPDX-License-Identifier: LGPL-2.1-or-later
"""Documents: the parametric stage objects headless, and plain results saved and reopened.

One module-scoped document runs the whole chain on the bundled cantilever (2 fit
iterations, ~10 s) from a copy of the STL that is deleted right after the import, so
every later step (recompute, save, reopen, recompute) proves the document is
self-contained.
"""
import os
import shutil

import numpy as np
import pytest

import FreeCAD

from core.polymesh_io import write_polymesh
from core.subdivision import sample_cages

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SAMPLE = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
KINDS = ("Target", "Segmentation", "BaseMesh", "Fit", "Solid")


class RunLog:
    """Records which stage objects actually ran their stage (not just redisplayed)."""

    def __init__(self, objects):
        self.ran = []
        for obj in objects:
            original = obj.Proxy.run

            def run(o, progress, original=original):
                self.ran.append(o.Name)
                return original(o, progress)

            obj.Proxy.run = run


@pytest.fixture(scope="module")
def chain_file(tmp_path_factory):
    """Path of a saved document holding the recomputed chain (source STL deleted)."""
    from polycube_wb import api

    folder = tmp_path_factory.mktemp("chain")
    source = folder / "cantilever.stl"
    shutil.copy(SAMPLE, source)
    doc = FreeCAD.newDocument("PolycubeChain")
    target = api.make_target(doc, str(source), check_self_intersections=False)
    os.remove(source)
    chain = api.make_chain(doc, target, "Solid", Fit={"Iterations": 2})
    outcome = api.recompute(doc)
    assert outcome.ok, outcome.failures
    path = str(folder / "chain.FCStd")
    doc.saveAs(path)
    FreeCAD.closeDocument(doc.Name)
    assert sorted(chain) == sorted(KINDS)
    return path


@pytest.fixture
def chain_doc(chain_file, tmp_path):
    """A fresh copy of the saved chain document, opened (undo on), closed afterwards."""
    copy = str(tmp_path / "copy.FCStd")
    shutil.copy(chain_file, copy)
    doc = FreeCAD.openDocument(copy)
    doc.UndoMode = 1
    yield doc
    FreeCAD.closeDocument(doc.Name)


def _objects(doc):
    from polycube_wb import api

    return {api.stage_kind(obj): obj for obj in doc.Objects if api.stage_kind(obj)}


def test_reopened_chain_has_its_proxies_and_results(chain_doc):
    from polycube_wb.objects.cage import read_cage
    from polycube_wb.objects.fit import FitProxy
    from polycube_wb.objects.target import TargetProxy

    objects = _objects(chain_doc)
    assert sorted(objects) == sorted(KINDS)
    assert isinstance(objects["Target"].Proxy, TargetProxy)
    assert isinstance(objects["Fit"].Proxy, FitProxy)
    for obj in objects.values():
        assert obj.Status == "ok" and obj.isValid(), (obj.Name, obj.Status)
        assert obj.State == ["Up-to-date"], (obj.Name, obj.State)
    target, seg = objects["Target"], objects["Segmentation"]
    assert target.Mesh.CountFacets == target.Triangles == 15388
    assert target.Mesh.isSolid() and target.Genus == 0
    assert len(seg.FaceLabel) == len(seg.FaceColors) == target.Triangles
    assert set(seg.FaceLabel) == set(range(6)) and seg.Valid
    for kind in ("BaseMesh", "Fit"):
        cage = read_cage(objects[kind])
        shape = objects[kind].Shape
        assert cage.n_faces == objects[kind].Faces > 6
        # The shape's first vertices are the cage vertices, in order (the saved B-rep
        # keeps about 15 significant digits).
        first = np.array([[v.X, v.Y, v.Z] for v in shape.Vertexes[:len(cage.vertices)]])
        assert np.abs(first - cage.vertices).max() < 1e-9 * shape.BoundBox.DiagonalLength
    # one part: the cage is built on the segmentation's own labeling, and says so
    assert objects["BaseMesh"].LabelingUsed == "the labeling stage's (1 part)"
    base, fitted = read_cage(objects["BaseMesh"]), read_cage(objects["Fit"])
    assert np.array_equal(base.face_vertices, fitted.face_vertices)
    assert np.abs(base.vertices - fitted.vertices).max() > 0, "the fit moved the cage"
    # both one-sided figures, each below 2% of the diagonal on the cantilever
    assert 0 < objects["Fit"].MeanDistance < objects["Fit"].MaxDistance < 0.02
    assert 0 < objects["Fit"].TargetMaxDistance < 0.02
    solid = objects["Solid"].Shape
    assert solid.isValid() and len(solid.Solids) == 1 and solid.Shells[0].isClosed()
    assert objects["Solid"].BrepFaces == len(solid.Faces) == base.n_faces
    # Colouring by part instead of label recolours without touching anything.
    by_label = list(seg.FaceColors)
    seg.ColourBy = "Parts"
    assert seg.State == ["Up-to-date"]
    assert len(set(seg.FaceColors)) == seg.Parts == 1 and seg.FaceColors != by_label


def test_parameter_change_reruns_that_stage_and_later_without_the_file(chain_doc):
    from polycube_wb import api

    objects = _objects(chain_doc)
    log = RunLog(objects.values())
    volume = objects["Solid"].Shape.Volume
    objects["Fit"].Mode = "best-fit"  # surely another surface (more or fewer inside
    # iterations can leave it where the pulled-inside start put it)
    outcome = api.recompute(chain_doc)
    assert outcome.ok, outcome.failures
    assert log.ran == [objects["Fit"].Name, objects["Solid"].Name]
    assert objects["Solid"].Shape.isValid()
    assert objects["Solid"].Shape.Volume != pytest.approx(volume, rel=1e-9)
    log.ran.clear()
    assert api.recompute(chain_doc).ok and log.ran == [], "nothing changed, nothing reruns"


def test_fit_tolerance_is_a_parameter_and_its_refinement_is_reported(chain_doc):
    """The Fit's ``Tolerance`` (mm) reruns the fit with the refinement; a tolerance the
    first fit meets keeps the cage and says so, 0 reports nothing."""
    from polycube_wb import api

    objects = _objects(chain_doc)
    fit = objects["Fit"]
    assert fit.Tolerance == 0.0 and fit.Refinement == ""
    faces = fit.Faces
    diagonal = objects["Target"].Mesh.BoundBox.DiagonalLength
    log = RunLog(objects.values())
    fit.Tolerance = 0.5 * diagonal
    assert api.recompute(chain_doc).ok
    assert log.ran == [fit.Name], "the same fitted cage: the solid does not rerun"
    assert fit.Refinement.startswith(f"tolerance met ({0.5 * diagonal:.4g} mm; faces {faces};")
    assert fit.Faces == faces and objects["Solid"].Shape.isValid()
    fit.Tolerance = 0.0
    assert api.recompute(chain_doc).ok and fit.Refinement == ""


def test_crease_curves_line_only_for_creased_cages(chain_doc):
    """The cantilever's cage has no creases: its Fit's ``CreaseCurves`` line stays empty;
    a creased cage's report gives the counts."""
    from polycube_wb.objects.fit import crease_curves_summary

    assert _objects(chain_doc)["Fit"].CreaseCurves == ""
    assert crease_curves_summary(None) == ""
    assert crease_curves_summary({"matched": 298, "creases": 304, "held_back": 17}) == (
        "298 of 304 crease edges fitted to the target's feature lines, 17 vertices held back "
        "where the surface would cross itself")


def test_outside_refinement_line_names_the_goal_the_fits_and_the_cage_kept():
    from polycube_wb.objects.fit import outside_refinement_summary

    assert outside_refinement_summary(None) == ""
    section = {"goal": 0.003, "reason": "0.074% of the volume outside after 1 refinement",
               "faces": 523, "rounds": [{"faces": 320}, {"faces": 523}]}
    assert outside_refinement_summary(section) == (
        "volume outside above 0.30%: 0.074% of the volume outside after 1 refinement "
        "(faces 320 -> 523; kept 523)")


def test_edited_fitted_cage_moves_the_solid_without_refitting(chain_doc):
    from polycube_wb import api

    objects = _objects(chain_doc)
    fit, solid = objects["Fit"], objects["Solid"]
    log = RunLog(objects.values())
    before = solid.Shape.BoundBox
    points = list(fit.CageVertices)
    top = max(range(len(points)), key=lambda k: points[k].z)
    moved = points[top] + FreeCAD.Vector(0, 0, 5.0)
    api.move_cage_vertices(fit, {top: (moved.x, moved.y, moved.z)})
    assert api.recompute(chain_doc).ok
    assert log.ran == [solid.Name], "only the solid reruns"
    assert fit.CageVertices[top].z == pytest.approx(points[top].z + 5.0)
    assert [p for k, p in enumerate(fit.CageVertices) if k != top] == \
        [p for k, p in enumerate(points) if k != top]
    after = solid.Shape.BoundBox
    assert solid.Shape.isValid()
    assert after.ZMax > before.ZMax + 0.5, "the solid follows the moved vertex"


def test_a_cage_edit_that_folds_the_limit_surface_is_refused_by_the_solid(chain_doc):
    from polycube_wb import api

    objects = _objects(chain_doc)
    fit, solid = objects["Fit"], objects["Solid"]
    points = list(fit.CageVertices)
    top = max(range(len(points)), key=lambda k: points[k].z)
    lowest = min(p.z for p in points)
    # the top vertex pushed through the part, below its bottom: the surface folds through itself
    api.move_cage_vertices(fit, {top: (points[top].x, points[top].y, lowest - 20.0)})
    outcome = api.recompute(chain_doc)
    assert list(outcome.failures) == [solid.Name]
    assert "the limit surface intersects itself" in solid.Status and "\n" not in solid.Status
    assert fit.isValid() and fit.Status == "ok"


def test_cage_edits_are_checked(chain_doc):
    from core.errors import ParameterError
    from polycube_wb import api

    objects = _objects(chain_doc)
    count = len(objects["BaseMesh"].CageVertices)
    with pytest.raises(ParameterError, match=f"is not a cage vertex index \\(0..{count - 1}\\)"):
        api.move_cage_vertices(objects["BaseMesh"], {count: (0, 0, 0)})
    with pytest.raises(ParameterError, match="3 finite numbers"):
        api.move_cage_vertices(objects["BaseMesh"], {0: (0, float("nan"), 0)})
    with pytest.raises(ParameterError, match="not a BaseMesh or Fit"):
        api.move_cage_vertices(objects["Solid"], {0: (0, 0, 0)})


def test_cancel_during_a_refit_marks_the_fit_and_undo_restores_it(chain_doc):
    from core.errors import Cancelled
    from core.progress import Progress
    from polycube_wb import api

    class CancelDuringFit(Progress):
        """Cancels at the first report from inside the fit's iterations."""

        def __init__(self):
            self.seen = []

        def report(self, stage, fraction, message=""):
            self.seen.append((stage, fraction))

        def check_cancel(self):
            if any(stage == "fit" for stage, _ in self.seen):
                raise Cancelled("test: Esc")

    objects = _objects(chain_doc)
    fit, solid = objects["Fit"], objects["Solid"]
    cage, volume, undo = list(fit.CageVertices), solid.Shape.Volume, chain_doc.UndoCount
    progress = CancelDuringFit()

    def build():
        fit.Iterations = 40

    with pytest.raises(Cancelled, match=f"cancelled by the user at {fit.Label}"):
        api.run_in_transaction(chain_doc, "Refit", build, progress)
    fractions = [fraction for stage, fraction in progress.seen]
    assert fractions == sorted(fractions), "one bar for the whole run, never backwards"
    assert fit.Iterations == 40, "the edit stays, to be run again"
    assert list(fit.CageVertices) == cage, "the fit keeps its last result, no half result"
    assert fit.Status == "cancelled by the user" and "Touched" in fit.State
    assert solid.Shape.Volume == pytest.approx(volume, rel=1e-12) and solid.isValid(), \
        "the solid still matches the fit's (kept) result; it reruns when the fit does"
    assert objects["BaseMesh"].State == ["Up-to-date"]
    assert chain_doc.UndoCount == undo + 1
    chain_doc.undo()
    assert fit.Iterations == 2 and list(fit.CageVertices) == cage
    assert fit.State == ["Up-to-date"] and solid.State == ["Up-to-date"]
    assert fit.isValid() and fit.Status == "ok"
    chain_doc.redo()
    assert fit.Iterations == 40 and fit.Status == "cancelled by the user"
    assert "Touched" in fit.State, "redone: the fit is to be run again"


def test_failed_stage_is_invalid_with_a_one_line_status_others_intact(chain_doc):
    from polycube_wb import api

    objects = _objects(chain_doc)
    solid, fit = objects["Solid"], objects["Fit"]
    deviation = api.make_deviation(chain_doc, solid, objects["Target"])
    solid.Depth = 0
    outcome = api.recompute(chain_doc)
    assert list(outcome.failures) == [solid.Name]
    assert not solid.isValid() and "Invalid" in solid.State
    assert solid.Status.startswith("Depth must be between 1 and") and "\n" not in solid.Status
    assert fit.isValid() and fit.Status == "ok"
    assert deviation.Status == "" and deviation.Mesh.CountFacets == 0, "not run after a failure"
    solid.Depth = 8
    assert api.recompute(chain_doc).ok
    assert solid.isValid() and solid.Status == "ok"


def test_deviation_map_colours_and_figures(chain_doc):
    from polycube_wb import api

    objects = _objects(chain_doc)
    target, solid = objects["Target"], objects["Solid"]
    deviation = api.make_deviation(chain_doc, solid, target)
    assert api.recompute(chain_doc).ok
    diagonal = target.Mesh.BoundBox.DiagonalLength
    assert deviation.Mesh.CountPoints == len(deviation.VertexColors) == \
        len(deviation.SignedDistance) > 1000
    assert deviation.Watertight
    assert 0 < deviation.MeanDeviation <= deviation.MaxDeviation < 0.1 * diagonal
    assert deviation.MaxDeviationPercent == pytest.approx(
        100 * deviation.MaxDeviation / diagonal, rel=1e-6)
    assert 0 <= deviation.OutsideVolume < 20 and 0 <= deviation.UncoveredVolume < 50
    signed = np.asarray(deviation.SignedDistance)
    colours = np.asarray(deviation.VertexColors)[:, :3]
    worst = int(np.argmax(np.abs(signed)))
    # The scale covers the largest distance, the vertices' and the one searched both ways.
    assert deviation.ScaleUsed == pytest.approx(max(abs(signed[worst]), deviation.MaxDeviation))
    # Its marked point lies on the tessellation's box, where the largest distance is.
    box = deviation.Mesh.BoundBox
    assert box.isInside(deviation.MaxDeviationAt)
    log = RunLog([deviation])
    deviation.Scale = abs(signed[worst])
    assert api.recompute(chain_doc).ok
    assert log.ran == [], "a new colour scale only recolours"
    assert deviation.ScaleUsed == pytest.approx(abs(signed[worst]))
    # The vertex at the largest distance has the full end colour of its side, one at a
    # quarter of the scale is half-way from white.
    colours = np.asarray(deviation.VertexColors)[:, :3]
    end = (0.85, 0.13, 0.13) if signed[worst] > 0 else (0.13, 0.31, 0.85)
    assert np.allclose(colours[worst], end, atol=0.01)
    quarter = _deviation_colours(np.array([signed[worst] / 4]), abs(signed[worst]))[0]
    assert np.allclose(quarter, (np.asarray(end) + 0.95) / 2, atol=0.01)
    deviation.Scale = abs(signed[worst]) / 4
    assert api.recompute(chain_doc).ok
    assert np.mean(np.all(np.isclose(np.asarray(deviation.VertexColors)[:, :3], end, atol=0.01),
                          axis=1)) > 0.0


def _deviation_colours(signed, scale):
    from polycube_wb.objects.deviation import deviation_colours

    return deviation_colours(signed, scale)


def test_the_largest_deviation_counts_what_the_solid_misses():
    """A 10 mm cube against a target cube with a 3 mm pyramid on its top face: the solid's
    tessellation vertices all lie on the target (its corners), but the pyramid's apex lies
    3 mm above the solid, and the largest deviation says so (both ways, to 1e-4 of the
    diagonal)."""
    import Mesh
    import Part

    from polycube_wb import api

    doc = FreeCAD.newDocument("spike")
    try:
        solid = doc.addObject("Part::Feature", "Cube")
        solid.Shape = Part.makeBox(10, 10, 10)
        corners = [(x, y, z) for z in (0, 10) for y in (0, 10) for x in (0, 10)]
        apex = (5, 5, 13)
        facets = [(0, 2, 3), (0, 3, 1), (0, 1, 5), (0, 5, 4), (1, 3, 7), (1, 7, 5),
                  (3, 2, 6), (3, 6, 7), (2, 0, 4), (2, 4, 6),
                  (4, 5, 8), (5, 7, 8), (7, 6, 8), (6, 4, 8)]  # 8: the apex
        points = corners + [apex]
        target = doc.addObject("Mesh::Feature", "Target")
        target.Mesh = Mesh.Mesh([[points[i] for i in facet] for facet in facets])
        deviation = api.make_deviation(doc, solid, target)
        assert api.recompute(doc).ok
        diagonal = np.sqrt(10 ** 2 + 10 ** 2 + 13 ** 2)
        assert np.abs(np.asarray(deviation.SignedDistance)).max() < 1e-9  # the corners
        assert deviation.MaxDeviation == pytest.approx(3.0, abs=1e-4 * diagonal)
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_moving_the_target_moves_the_labeling(tmp_path):
    from polycube_wb import api

    doc = FreeCAD.newDocument("PolycubeMove")
    try:
        target = api.make_target(doc, SAMPLE, check_self_intersections=False)
        seg = api.make_segmentation(doc, target)
        assert api.recompute(doc).ok
        before = seg.Mesh.BoundBox
        log = RunLog([target, seg])
        target.Placement.Base = FreeCAD.Vector(50.0, 0.0, 0.0)
        assert api.recompute(doc).ok
        assert log.ran == [target.Name, seg.Name]
        after = seg.Mesh.BoundBox
        assert after.XMin == pytest.approx(before.XMin + 50.0, abs=1e-6)
        assert after.YMin == pytest.approx(before.YMin, abs=1e-6)
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_bad_input_and_links_give_clear_errors(tmp_path):
    from core.errors import InvalidMeshError, ParameterError
    from polycube_wb import api

    open_mesh = tmp_path / "open.stl"
    open_mesh.write_text("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                         "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n")
    doc = FreeCAD.newDocument("PolycubeBad")
    try:
        with pytest.raises(InvalidMeshError):
            api.make_target(doc, str(open_mesh))
        assert doc.Objects == []
        target = api.make_target(doc, SAMPLE, check_self_intersections=False)
        with pytest.raises(ParameterError, match="Segmentation has no property 'Lamda'"):
            api.make_segmentation(doc, target, Lamda=0.3)
        assert [obj.Name for obj in doc.Objects] == [target.Name]
        fit = api.make_fit(doc, None)
        outcome = api.recompute(doc)
        assert "'BaseMesh' link must point to a Polycube stage object" in outcome.failures[fit.Name]
        assert not fit.isValid() and target.isValid()
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_old_plain_target_document_opens_and_converts(tmp_path):
    """Documents of the previous version hold a plain Mesh::Feature with PolycubeSource."""
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target
    from polycube_wb import api
    from polycube_wb.document import add_target_mesh

    mesh, _ = validate_target(*read_triangle_soup(SAMPLE), check_self_intersections=False)
    doc = FreeCAD.newDocument("PolycubeOld")
    old = add_target_mesh(doc, mesh, "cantilever_target")
    old.addProperty("App::PropertyFile", "PolycubeSource", "Polycube", "Mesh file")
    old.PolycubeSource = "/nonexistent/cantilever.stl"
    path = str(tmp_path / "old.FCStd")
    doc.saveAs(path)
    FreeCAD.closeDocument(doc.Name)
    reopened = FreeCAD.openDocument(path)
    try:
        old = reopened.getObject("cantilever_target")
        target = api.make_target(reopened, old, check_self_intersections=False)
        assert target.Mesh.CountFacets == old.Mesh.CountFacets == len(mesh.faces)
        assert target.SourceFile == "/nonexistent/cantilever.stl"
        assert api.recompute(reopened).ok and target.Genus == 0
    finally:
        FreeCAD.closeDocument(reopened.Name)


def test_preferences_give_new_objects_their_defaults():
    from polycube_wb import api
    from polycube_wb.preferences import default, reset_defaults, set_default

    doc = FreeCAD.newDocument("PolycubePrefs")
    try:
        set_default("fit_iterations", 7)
        set_default("lam", 0.25)
        set_default("fit_mode", "best-fit")
        fit = api.make_fit(doc, None)
        assert fit.Iterations == 7 and fit.Mode == "best-fit" and default("lam") == 0.25
        assert fit.Proxy.parameters(fit)["fit_t_min"] is None, "automatic by default"
        fit.AutoMinThickness = False
        fit.MinThickness = 0.5
        assert fit.Proxy.parameters(fit)["fit_t_min"] == 0.5
        assert fit.Proxy.parameters(fit)["outside_refinement"] == fit.OutsideRefinement == 0.003
        fit.OutsideRefinement = 0.0
        assert fit.Proxy.parameters(fit)["outside_refinement"] == 0.0
        set_default("fit_iterations", 100)  # the paper's value: stored as no preference
        assert default("fit_iterations") == 100
    finally:
        reset_defaults()
        FreeCAD.closeDocument(doc.Name)
    assert default("lam") == 0.5 and default("fit_iterations") == 100
    assert default("fit_mode") == "inside"


def test_plain_results_reopen_and_are_checked_and_exported(tmp_path):
    """api.reconstruct's plain objects, saved and reopened, still work with our code: the
    target's arrays come back (float32 in FreeCAD's mesh), the deviation map checks the
    reopened solid against the reopened target, and the solid exports to STEP."""
    from polycube_wb import api
    from polycube_wb.brep import tessellate
    from polycube_wb.convert import mesh_to_arrays
    from polycube_wb.document import add_solid, add_target_mesh
    from polycube_wb.step_io import read_step
    from core.types import TriMesh

    cage = tmp_path / "torus.obj"
    write_polymesh(cage, sample_cages.torus())
    solid, _ = api.subd_to_solid(cage, measure=False)
    diagonal = solid.BoundBox.DiagonalLength
    V, F = tessellate(solid, 1e-3 * diagonal)
    doc = FreeCAD.newDocument("PolycubePlainSave")
    add_target_mesh(doc, TriMesh(V, F), "Target")
    add_solid(doc, solid, "Solid")
    path = str(tmp_path / "saved.FCStd")
    doc.saveAs(path)
    FreeCAD.closeDocument(doc.Name)
    reopened = FreeCAD.openDocument(path)
    try:
        target, solid_obj = reopened.getObject("Target"), reopened.getObject("Solid")
        V2, F2 = mesh_to_arrays(target.Mesh)
        assert np.array_equal(F2, F)
        assert np.abs(V2 - V).max() <= 1e-6 * diagonal, "float32 rounding only"
        deviation = api.make_deviation(reopened, solid_obj, target)
        assert api.recompute(reopened).ok
        # The target is a chordal tessellation of the solid at a deflection of 1e-3 of the
        # diagonal; OpenCASCADE aims at that deflection without bounding it, so three times
        # it is the margin.
        assert 0 < deviation.MaxDeviationPercent < 0.3
        assert deviation.Watertight and deviation.UncoveredVolume < 0.1
        step = api.export_step(solid_obj, str(tmp_path / "reopened.step"))
        read = read_step(step)
        assert len(read.Solids) == 1 and len(read.Faces) == 48
        assert abs(read.Volume - solid.Volume) <= 1e-6 * solid.Volume
    finally:
        FreeCAD.closeDocument(reopened.Name)


def test_creased_cage_survives_the_document_and_its_obj(tmp_path):
    """A cage's crease tags are stored in the document (``CageCreases``) and come back after
    save and reopen; the OBJ of a creased cage gives the creased solid, whose volume is the
    creased limit surface's, not the smooth one's."""
    from core.subdivision.limit import limit_volume
    from core.types import PolyMesh
    from polycube_wb import api
    from polycube_wb.objects.cage import add_cage_properties, read_cage, store_cage

    cube = sample_cages.cube(10.0)
    creased = PolyMesh(cube.vertices, cube.face_vertices, cube.face_offsets,
                       np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64))
    doc = FreeCAD.newDocument("PolycubeCreases")
    holder = doc.addObject("App::FeaturePython", "Cage")
    add_cage_properties(holder)
    store_cage(holder, creased)
    path = str(tmp_path / "creases.FCStd")
    doc.saveAs(path)
    FreeCAD.closeDocument(doc.Name)
    reopened = FreeCAD.openDocument(path)
    try:
        back = read_cage(reopened.getObject("Cage"))
        assert np.array_equal(back.creases, creased.creases)
        assert np.array_equal(back.vertices, creased.vertices)
    finally:
        FreeCAD.closeDocument(reopened.Name)
    obj_path = tmp_path / "creased.obj"
    write_polymesh(obj_path, creased)
    solid, _ = api.subd_to_solid(obj_path, measure=False)
    assert solid.isValid()
    assert solid.Volume == pytest.approx(limit_volume(creased), rel=1e-4)
    assert solid.Volume > 1.05 * limit_volume(cube)


def test_package_manifest_parses():
    meta = FreeCAD.Metadata(os.path.join(REPO, "package.xml"))
    workbench = meta.Content["workbench"][0]
    assert meta.Name == "Polycube" and workbench.Classname == "PolycubeWorkbench"
    assert os.path.isfile(os.path.join(REPO, meta.Icon))
    with open(os.path.join(REPO, "polycube_wb", "gui", "workbench.py"), encoding="utf-8") as handle:
        assert f"class {workbench.Classname}" in handle.read()


def test_a_damaged_mesh_is_repaired_as_on_the_command_line(tmp_path):
    """The Target's import runs the command line's intake: a sphere with a zero-area cap,
    a duplicate face and inward normals becomes the same closed outward mesh; without
    repair it is refused and nothing is added."""
    import trimesh

    from core.errors import InvalidMeshError
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target
    from polycube_wb import api

    sphere = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.array(sphere.vertices), np.array(sphere.faces)[:, ::-1]
    a, b, c = F[100]
    V[c] = (V[a] + V[b]) / 2
    path = str(tmp_path / "damaged.obj")
    with open(path, "w") as handle:  # every digit: the cap stays of zero area
        handle.writelines("v %r %r %r\n" % tuple(p) for p in V)
        handle.writelines("f %d %d %d\n" % tuple(f + 1) for f in np.vstack([F, F[7:8]]))
    mesh, summary = validate_target(*read_triangle_soup(path))
    assert {entry["kind"] for entry in summary["repairs"]} == \
        {"duplicate_faces", "reoriented_faces", "zero_area_faces"}
    doc = FreeCAD.newDocument("PolycubeRepair")
    try:
        with pytest.raises(InvalidMeshError):
            api.make_target(doc, path, repair=False)
        assert doc.Objects == []
        target = api.make_target(doc, path)
        assert api.recompute(doc).ok and target.Genus == 0
        points = np.array([[p.x, p.y, p.z] for p in target.Mesh.Points])
        facets = np.array([f.PointIndices for f in target.Mesh.Facets])
        assert len(facets) == len(mesh.faces) == len(F)
        assert np.allclose(points[facets], mesh.vertices[mesh.faces], atol=1e-6)
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_solid_faces_property_merges_blocks_of_quads(chain_doc):
    """Export g1 with Faces chart: one face per block of quads, fewer than the quads, the same
    solid (FreeCAD's volume integration is coarser on multi-span faces, hence 1e-3); Faces
    chart with the exact form is refused with a one-line status naming g1."""
    from polycube_wb import api

    objects = _objects(chain_doc)
    solid = objects["Solid"]
    solid.Export = "g1"
    assert api.recompute(chain_doc).ok
    per_quad = (len(solid.Shape.Faces), solid.Shape.Volume)
    solid.Faces = "chart"
    assert api.recompute(chain_doc).ok
    assert solid.isValid() and solid.Shape.isValid() and solid.BrepFaces == len(solid.Shape.Faces)
    assert len(solid.Shape.Faces) < per_quad[0]
    assert solid.Shape.Volume == pytest.approx(per_quad[1], rel=1e-3)
    solid.Export = "exact"
    assert list(api.recompute(chain_doc).failures) == [solid.Name]
    assert "g1" in solid.Status and "\n" not in solid.Status

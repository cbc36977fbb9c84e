# SPDX-License-Identifier: LGPL-2.1-or-later
"""Workbench tests that run inside the real FreeCAD GUI (loaded by TestPolycubeGui.py).

Every case makes its own document and closes it, and file dialogs and message boxes
are replaced by stubs, so the run needs no user and leaves nothing behind except the
screenshots in ``$POLYCUBE_GUI_OUTPUT`` (default ``tests/gui/output/``).
"""
import os
import shutil
import tempfile
import unittest

import FreeCAD
import FreeCADGui

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUTPUT = os.environ.get("POLYCUBE_GUI_OUTPUT") or os.path.join(REPO, "tests", "gui", "output")
TARGET_MESH = os.path.normpath(os.path.join(REPO, "..", "shared", "data", "meshes",
                                            "to_simp_lbracket.stl"))
SAMPLE_MESH = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
WORKBENCH = "PolycubeWorkbench"
SCREENSHOT_SIZE = (1024, 768)
MIN_COVERED = 0.03
"""Least fraction of non-background pixels for a screenshot to count as showing the model."""


def _commands():
    from polycube_wb.gui import commands

    return commands


def save_screenshot(doc, file_name):
    """Isometric, fit-all screenshot of ``doc``'s 3D view on white; returns the path."""
    os.makedirs(OUTPUT, exist_ok=True)
    view = FreeCADGui.getDocument(doc.Name).ActiveView
    view.viewIsometric()
    view.fitAll()
    FreeCADGui.updateGui()
    path = os.path.join(OUTPUT, file_name)
    view.saveImage(path, SCREENSHOT_SIZE[0], SCREENSHOT_SIZE[1], "White")
    return path


def image_figures(path, columns=128, rows=96):
    """(width, height, distinct colours, covered fraction) of a screenshot.

    Colours and coverage (pixels that are not pure white) are counted on a
    ``columns x rows`` nearest-neighbour sample of the image.
    """
    from PySide import QtCore, QtGui

    image = QtGui.QImage(path)
    small = image.scaled(columns, rows, QtCore.Qt.IgnoreAspectRatio,
                         QtCore.Qt.FastTransformation)
    colours = set()
    covered = 0
    for y in range(rows):
        for x in range(columns):
            rgb = small.pixel(x, y) & 0xFFFFFF
            colours.add(rgb)
            covered += rgb != 0xFFFFFF
    return image.width(), image.height(), len(colours), covered / float(columns * rows)


class _DocumentCase(unittest.TestCase):
    """A fresh document and temporary folder per test; stubs for dialogs and boxes."""

    def setUp(self):
        self.commands = _commands()
        self.doc = FreeCAD.newDocument("PolycubeGuiTest")
        FreeCADGui.activateWorkbench(WORKBENCH)
        self.tmp = tempfile.mkdtemp(prefix="polycube_gui_")
        self.boxes = []
        self._saved = (self.commands.ask_open_file, self.commands.message_box)
        self.commands.message_box = lambda kind, title, text: self.boxes.append((kind, text))

    def tearDown(self):
        self.commands.ask_open_file, self.commands.message_box = self._saved
        FreeCAD.closeDocument(self.doc.Name)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def write_cage(self, cage, name):
        from core.polymesh_io import write_polymesh

        path = os.path.join(self.tmp, name)
        write_polymesh(path, cage)
        return path

    def answer_open_dialog(self, path):
        self.commands.ask_open_file = lambda *args, **kwargs: path

    def assert_screenshot_shows_model(self, path):
        width, height, colours, covered = image_figures(path)
        self.assertEqual((width, height), SCREENSHOT_SIZE)
        self.assertGreater(colours, 20, f"{path}: only {colours} colours, looks empty")
        self.assertGreater(covered, MIN_COVERED,
                           f"{path}: only {covered:.1%} of the pixels show the model")


class WorkbenchTest(unittest.TestCase):
    """The workbench registers, activates and shows its commands."""

    def test_activate_lists_commands_and_toolbar(self):
        commands = _commands()
        self.assertIn(WORKBENCH, FreeCADGui.listWorkbenches())
        FreeCADGui.activateWorkbench(WORKBENCH)
        workbench = FreeCADGui.activeWorkbench()
        self.assertEqual(workbench.name(), WORKBENCH)
        known = set(FreeCADGui.listCommands())
        ids = [command.ID for command in commands.COMMANDS]
        self.assertEqual(len(ids), 9)
        for command_id in ids:
            self.assertTrue(command_id.startswith("PolyCube_"))
            self.assertIn(command_id, known)
            self.assertTrue(os.path.isfile(FreeCADGui.Command.get(command_id)
                                           .getInfo()["pixmap"]), command_id)
        self.assertIn("Polycube", workbench.listToolbars())
        self.assertEqual(workbench.getToolbarItems()["Polycube"], ids)
        self.assertIn("Polycube", workbench.listMenus())
        from PySide import QtGui

        bars = [bar for bar in FreeCADGui.getMainWindow().findChildren(QtGui.QToolBar)
                if bar.windowTitle() == "Polycube"]
        self.assertEqual(len(bars), 1)
        self.assertTrue(bars[0].isVisible())
        self.assertEqual(len(bars[0].actions()), len(ids))

    def test_stage_commands_are_active_with_a_document(self):
        FreeCADGui.activateWorkbench(WORKBENCH)
        doc = FreeCAD.newDocument("PolycubeGuiActive")
        try:
            for command_id in ("PolyCube_ImportTarget", "PolyCube_SegmentParts",
                               "PolyCube_LabelPolycube", "PolyCube_BuildBaseMesh",
                               "PolyCube_FitTarget", "PolyCube_ReconstructAll",
                               "PolyCube_ImportSubD"):
                command = FreeCADGui.Command.get(command_id)
                self.assertTrue(command.isActive(), command_id)
                self.assertNotIn("not available", command.getInfo()["menuText"].lower())
        finally:
            FreeCAD.closeDocument(doc.Name)


class SubDSolidTest(_DocumentCase):
    """SubD cage -> B-spline solid: geometry, undo, screenshot, STEP, check."""

    def test_torus_cage_to_solid_undo_and_screenshot(self):
        from core.subdivision.sample_cages import torus

        path = self.write_cage(torus(), "torus.obj")
        undo_before = self.doc.UndoCount
        obj, report = self.commands.import_subd_cage(self.doc, path)
        shape = obj.Shape
        self.assertTrue(obj.isDerivedFrom("Part::Feature"))
        self.assertTrue(shape.isValid())
        self.assertEqual(len(shape.Solids), 1)
        self.assertEqual(len(shape.Faces), 48)
        self.assertTrue(all(shell.isClosed() for shell in shape.Shells))
        self.assertEqual(len(shape.Shells), 1)
        # Genus 1: Euler characteristic V - E + F of the B-rep is 0 for a torus.
        self.assertEqual(len(shape.Vertexes) - len(shape.Edges) + len(shape.Faces), 0)
        limit = report["brep"]["limit_volume"]
        self.assertLess(abs(shape.Volume - limit) / limit, 1e-5)
        self.assertEqual(self.doc.UndoCount, undo_before + 1)
        self.assertIn("Import SubD cage as solid", self.doc.UndoNames)

        shot = save_screenshot(self.doc, "polycube_torus_solid.png")
        self.assert_screenshot_shows_model(shot)

        name = obj.Name
        self.doc.undo()
        self.assertIsNone(self.doc.getObject(name))
        self.assertEqual(len(self.doc.Objects), 0)

    def test_command_runs_through_the_gui_and_undoes(self):
        from core.subdivision.sample_cages import cube

        self.answer_open_dialog(self.write_cage(cube(10.0), "cube.obj"))
        FreeCADGui.runCommand("PolyCube_ImportSubD")
        solids = [obj for obj in self.doc.Objects if obj.isDerivedFrom("Part::Feature")]
        self.assertEqual(self.boxes, [])
        self.assertEqual(len(solids), 1)
        self.assertTrue(solids[0].Shape.isValid())
        self.assertEqual(len(solids[0].Shape.Faces), 6)
        self.doc.undo()
        self.assertEqual(len(self.doc.Objects), 0)

    def test_bad_cage_reports_warning_and_changes_nothing(self):
        path = os.path.join(self.tmp, "open.obj")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
        self.answer_open_dialog(path)
        FreeCADGui.runCommand("PolyCube_ImportSubD")
        self.assertEqual(len(self.doc.Objects), 0)
        self.assertEqual(len(self.boxes), 1)
        self.assertEqual(self.boxes[0][0], "warning")

    def test_export_step_and_check_against_a_target(self):
        import Part  # after FreeCAD (imported at module level): the reverse order segfaults

        from core.subdivision.sample_cages import torus
        from polycube_wb.brep import tessellate
        from polycube_wb.convert import arrays_to_mesh

        obj, _ = self.commands.import_subd_cage(self.doc, self.write_cage(torus(), "t.obj"))
        step = self.commands.export_step(obj, os.path.join(self.tmp, "torus.step"))
        read = Part.read(step)
        self.assertEqual(len(read.Solids), 1)
        self.assertLess(abs(read.Volume - obj.Shape.Volume) / obj.Shape.Volume, 1e-6)

        diagonal = obj.Shape.BoundBox.DiagonalLength
        V, F = tessellate(obj.Shape, 1e-3 * diagonal)
        target = self.doc.addObject("Mesh::Feature", "TorusTarget")
        target.Mesh = arrays_to_mesh(V, F)
        figures = self.commands.check_result(obj, target, samples=5000)
        self.assertTrue(figures["valid"])
        self.assertTrue(figures["closed"])
        self.assertTrue(figures["watertight"])
        # The target is a chordal tessellation (inside the surface, deviation <= 1e-3 of
        # the diagonal), so the solid sticks out of it a little and covers all of it.
        self.assertLess(figures["outside_volume_fraction"], 0.01)
        self.assertLess(figures["uncovered_volume_fraction"], 1e-3)
        self.assertLess(figures["distances"]["hausdorff"], 2e-3)


class TargetMeshTest(_DocumentCase):
    """Target mesh intake, labeling and Reconstruct all on the L-bracket."""

    def setUp(self):
        super().setUp()
        if not os.path.isfile(TARGET_MESH):
            self.fail(f"dev mesh missing: {TARGET_MESH} (the repo expects ../shared beside it)")

    def test_import_label_and_screenshots(self):
        obj, summary = self.commands.import_target_mesh(self.doc, TARGET_MESH)
        self.assertTrue(self.commands.is_target(obj))
        self.assertEqual(obj.Mesh.CountFacets, summary["triangles"])
        self.assertEqual(obj.Mesh.CountPoints, summary["vertices"])
        self.assertTrue(obj.Mesh.isSolid())
        self.assertEqual(getattr(obj, self.commands.SOURCE_PROPERTY), TARGET_MESH)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_target_mesh.png"))

        group, report = self.commands.label_polycube(self.doc, obj)
        for key in ("valid", "charts", "corners", "invalid_charts", "invalid_boundaries",
                    "invalid_corners", "turning_points"):
            self.assertIn(key, report)
        children = group.Group
        self.assertGreaterEqual(len(children), 6 if report["valid"] else 1)
        self.assertLessEqual(len(children), 6)
        self.assertEqual(sum(child.Mesh.CountFacets for child in children),
                         summary["triangles"])
        self.assertFalse(obj.ViewObject.Visibility)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_labels.png"))

        group_name = group.Name
        self.commands.label_polycube(self.doc, obj)
        groups = [o for o in self.doc.Objects if o.isDerivedFrom("App::DocumentObjectGroup")]
        self.assertEqual(len(groups), 1, "a second labeling replaces the first")
        self.doc.undo()
        self.assertIsNotNone(self.doc.getObject(group_name))

    def test_segment_parts_then_label_uses_them(self):
        obj, summary = self.commands.import_target_mesh(self.doc, TARGET_MESH,
                                                        check_self_intersections=False)
        group, section = self.commands.segment_parts(self.doc, obj)
        self.assertEqual(getattr(obj, self.commands.PARTS_PROPERTY), "auto")
        self.assertEqual(len(group.Group), section["parts"])
        self.assertGreaterEqual(section["parts"], 1)
        self.assertEqual(sum(child.Mesh.CountFacets for child in group.Group),
                         summary["triangles"])
        _, report = self.commands.label_polycube(self.doc, obj)
        self.assertEqual(report["parts"], section["parts"])

    def test_base_mesh_cage_is_shown_and_undoable(self):
        obj, _ = self.commands.import_target_mesh(self.doc, SAMPLE_MESH,
                                                  check_self_intersections=False)
        cage, section = self.commands.build_base_mesh(self.doc, obj)
        self.assertGreater(section["faces"], 6)
        self.assertEqual(section["faces"], section["quads"])
        self.assertGreater(len(cage.Shape.Edges), section["faces"])
        name = cage.Name
        self.doc.undo()
        self.assertIsNone(self.doc.getObject(name))
        FreeCADGui.Selection.clearSelection()
        FreeCADGui.Selection.addSelection(obj)
        FreeCADGui.runCommand("PolyCube_BuildBaseMesh")
        self.assertIsNotNone(self.doc.getObject(name), "the command builds the cage again")
        self.assertEqual(self.boxes, [])
        fitted, fit = self.commands.fit_to_target(self.doc, obj, fit_iterations=3)
        self.assertEqual(fit["iterations"], 3)
        self.assertLess(fit["outside_volume_fraction"], fit["initial_outside_volume_fraction"])
        self.assertGreater(len(fitted.Shape.Edges), section["faces"])

    def test_bad_target_is_rejected_through_the_command(self):
        path = os.path.join(self.tmp, "open.stl")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write("solid t\n")
            for tri in (((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((0, 0, 0), (0, 0, 1), (1, 0, 0))):
                handle.write("facet normal 0 0 0\nouter loop\n")
                handle.writelines(f"vertex {x} {y} {z}\n" for x, y, z in tri)
                handle.write("endloop\nendfacet\n")
            handle.write("endsolid t\n")
        from core.errors import InvalidMeshError

        with self.assertRaises(InvalidMeshError) as raised:
            self.commands.import_target_mesh(self.doc, path)
        self.assertEqual(raised.exception.reason, "open")
        self.answer_open_dialog(path)
        FreeCADGui.runCommand("PolyCube_ImportTarget")
        self.assertEqual(len(self.doc.Objects), 0)
        self.assertEqual([kind for kind, _ in self.boxes], ["warning"])
        self.assertIn(os.path.basename(path), self.boxes[0][1])

    def test_reconstruct_all_names_a_missing_stage(self):
        from core.errors import StageNotAvailableError

        with self.assertRaises(StageNotAvailableError) as raised:
            self.commands.reconstruct_all(self.doc, SAMPLE_MESH, parts="auto")
        self.assertIn("'basemesh' stage, which is not available yet", str(raised.exception))
        targets = [obj for obj in self.doc.Objects if self.commands.is_target(obj)]
        self.assertEqual(len(targets), 1)
        self.doc.undo()
        self.assertEqual(len(self.doc.Objects), 0)

    def test_reconstruct_all_builds_the_solid(self):
        solid = self.commands.reconstruct_all(self.doc, SAMPLE_MESH, fit_iterations=3)
        shape = solid.Shape
        self.assertTrue(shape.isValid())
        self.assertEqual(len(shape.Solids), 1)
        self.assertGreater(len(shape.Faces), 6)
        self.assertGreater(shape.Volume, 0)
        for obj in self.doc.Objects:
            if self.commands.is_target(obj) and obj.ViewObject is not None:
                obj.ViewObject.Visibility = False
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_reconstructed.png"))
        name = solid.Name
        self.doc.undo()
        self.assertIsNone(self.doc.getObject(name))


class ProgressTest(unittest.TestCase):
    """The progress adapter drives the GUI's status-bar progress indicator."""

    def test_stages_advance_and_stop(self):
        from polycube_wb.gui.fc_progress import FreeCADProgress

        with FreeCADProgress("GUI progress test") as progress:
            for stage in ("intake", "labeling"):
                for fraction in (0.0, 0.3, 1.0):
                    progress.report(stage, fraction)
                    progress.check_cancel()
        self.assertFalse(progress.cancelled)

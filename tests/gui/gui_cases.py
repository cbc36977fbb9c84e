# SPDX-License-Identifier: LGPL-2.1-or-later
"""Workbench tests that run inside the real FreeCAD GUI (loaded by TestPolycubeGui.py).

File dialogs and message boxes are replaced by stubs, so the run needs no user. The
workflow case runs the commands in the order a user would, on one document, in
numbered steps (unittest runs them in name order): import, segment parts, label, base
mesh, fit, solid, each task panel, a real Esc key press during the fit, the deviation
map, a cage edit, undo, save / reopen without the source file; bad files through the
import commands. Screenshots go to ``$POLYCUBE_GUI_OUTPUT`` (default ``tests/gui/output/``).
"""
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import FreeCAD
import FreeCADGui

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUTPUT = os.environ.get("POLYCUBE_GUI_OUTPUT") or os.path.join(REPO, "tests", "gui", "output")
SAMPLE_MESH = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
WORKBENCH = "PolycubeWorkbench"
SCREENSHOT_SIZE = (1024, 768)
MIN_COVERED = 0.03
"""Least fraction of non-background pixels for a screenshot to count as showing the model."""
FIT_ITERATIONS = 2
"""Fit iterations of the test chain (the preference is set to it for the run)."""


def _commands():
    from polycube_wb.gui import commands

    return commands


def save_screenshot(doc, file_name):
    """Isometric, fit-all screenshot of ``doc``'s 3D view on white; returns the path."""
    return save_view(doc, file_name, SCREENSHOT_SIZE, "White")


def save_view(doc, file_name, size, background="Current"):
    """Screenshot of ``doc``'s 3D view at ``size`` (width, height), isometric and fitted, on
    ``background`` (FreeCAD's own by default); returns the path."""
    os.makedirs(OUTPUT, exist_ok=True)
    view = FreeCADGui.getDocument(doc.Name).ActiveView
    view.viewIsometric()
    view.fitAll()
    FreeCADGui.updateGui()
    path = os.path.join(OUTPUT, file_name)
    view.saveImage(path, size[0], size[1], background)
    return path


def image_figures(path, columns=128, rows=96):
    """(width, height, distinct colours, covered fraction, colours) of a screenshot.

    Colours and coverage (pixels that are not pure white) are counted on a
    ``columns x rows`` nearest-neighbour sample of the image.
    """
    from PySide import QtCore, QtGui

    image = QtGui.QImage(path)
    small = image.scaled(columns, rows, QtCore.Qt.IgnoreAspectRatio,
                         QtCore.Qt.FastTransformation)
    colours = []
    for y in range(rows):
        for x in range(columns):
            colours.append(small.pixel(x, y) & 0xFFFFFF)
    covered = sum(rgb != 0xFFFFFF for rgb in colours) / float(columns * rows)
    return image.width(), image.height(), len(set(colours)), covered, colours


def _reddish_and_bluish(colours):
    """Counts of clearly red and clearly blue pixels (the deviation map's two ends)."""
    red = blue = 0
    for rgb in colours:
        r, g, b = rgb >> 16, (rgb >> 8) & 0xFF, rgb & 0xFF
        red += r > 150 and r > g + 60 and r > b + 60
        blue += b > 150 and b > r + 60 and b > g + 30
    return red, blue


class _Stubs:
    """Replaces the commands' dialogs and boxes (``polycube_wb.gui.dialogs``); restores them."""

    def __init__(self):
        from polycube_wb.gui import dialogs

        self.dialogs = dialogs
        self.boxes = []
        self.saved = (dialogs.ask_open_file, dialogs.message_box)
        dialogs.message_box = lambda kind, title, text: self.boxes.append((kind, text))

    def answer_open_dialog(self, path):
        self.dialogs.ask_open_file = lambda *args, **kwargs: path

    def restore(self):
        self.dialogs.ask_open_file, self.dialogs.message_box = self.saved


class _ScreenshotAssertions:
    def assert_screenshot_shows_model(self, path, min_colours=20, min_covered=MIN_COVERED):
        """The screenshot has its size, some colours and enough non-white pixels (a
        wireframe cage has two colours and covers less than a shaded surface)."""
        width, height, colours, covered, _ = image_figures(path)
        self.assertEqual((width, height), SCREENSHOT_SIZE)
        self.assertGreaterEqual(colours, min_colours, f"{path}: only {colours} colours")
        self.assertGreater(covered, min_covered,
                           f"{path}: only {covered:.1%} of the pixels show the model")


def report_view_text():
    """The text of FreeCAD's Report view (what a user reads there), once the messages
    posted to it are shown."""
    from PySide import QtGui

    QtGui.QApplication.processEvents()
    views = [widget for widget in FreeCADGui.getMainWindow().findChildren(QtGui.QTextEdit)
             if widget.objectName() == "Report view"]
    assert len(views) == 1, f"found {len(views)} Report views"
    return views[0].toPlainText()


def _objects(doc, kind):
    from polycube_wb import api

    return [obj for obj in doc.Objects if api.stage_kind(obj) == kind]


def _select(*objects):
    FreeCADGui.Selection.clearSelection()
    for obj in objects:
        FreeCADGui.Selection.addSelection(obj)


class EscapeKey:
    """Presses a real Esc key during the next long run.

    A Qt timer (it fires while the stage runs: FreeCAD's event loop keeps going) grabs the
    main window after ``after`` seconds, then posts an Esc key press to the main window;
    ``answered`` counts the question boxes it had to answer (a cancel asks none).
    """

    def __init__(self, after, grab_path):
        from PySide import QtCore

        self.after, self.grab_path = after, grab_path
        self.started = time.monotonic()
        self.sent = self.answered = 0
        self.grabbed = False
        self.timer = QtCore.QTimer()
        self.timer.setInterval(200)
        self.timer.timeout.connect(self._tick)
        self.timer.start()

    def _tick(self):
        from PySide import QtCore, QtGui

        box = QtGui.QApplication.activeModalWidget()
        if isinstance(box, QtGui.QMessageBox):
            box.button(QtGui.QMessageBox.Yes).click()
            self.answered += 1
            self.timer.stop()
            return
        if time.monotonic() - self.started < self.after:
            return
        if not self.grabbed:
            FreeCADGui.getMainWindow().grab().save(self.grab_path)
            self.grabbed = True
        event = QtGui.QKeyEvent(QtCore.QEvent.KeyPress, QtCore.Qt.Key_Escape,
                                QtCore.Qt.NoModifier)
        QtGui.QApplication.postEvent(FreeCADGui.getMainWindow(), event)
        self.sent += 1

    def stop(self):
        self.timer.stop()


class WorkbenchTest(unittest.TestCase):
    """The workbench registers, activates and shows its commands and preferences page."""

    def test_activate_lists_commands_toolbar_and_preferences(self):
        from PySide import QtGui

        from polycube_wb.gui.preferences import PreferencesPage

        commands = _commands()
        self.assertIn(WORKBENCH, FreeCADGui.listWorkbenches())
        FreeCADGui.activateWorkbench(WORKBENCH)
        workbench = FreeCADGui.activeWorkbench()
        self.assertEqual(workbench.name(), WORKBENCH)
        known = set(FreeCADGui.listCommands())
        ids = [command.ID for command in commands.COMMANDS]
        self.assertEqual(len(ids), 13)
        for command_id in ids:
            self.assertTrue(command_id.startswith("PolyCube_"))
            self.assertIn(command_id, known)
            self.assertTrue(os.path.isfile(FreeCADGui.Command.get(command_id)
                                           .getInfo()["pixmap"]), command_id)
        self.assertEqual(workbench.getToolbarItems()["Polycube"], ids)
        bars = [bar for bar in FreeCADGui.getMainWindow().findChildren(QtGui.QToolBar)
                if bar.windowTitle() == "Polycube"]
        self.assertEqual(len(bars), 1)
        self.assertTrue(bars[0].isVisible())
        page = PreferencesPage()
        page.loadSettings()
        widget, _ = page.widgets["fit_iterations"]
        self.assertEqual(widget.value(), 100, "the paper's default")


class SubDSolidTest(unittest.TestCase, _ScreenshotAssertions):
    """SubD cage -> B-spline solid through the command: geometry, undo, screenshot."""

    def setUp(self):
        self.stubs = _Stubs()
        self.doc = FreeCAD.newDocument("PolycubeSubD")
        FreeCADGui.activateWorkbench(WORKBENCH)
        self.tmp = tempfile.mkdtemp(prefix="polycube_gui_")

    def tearDown(self):
        self.stubs.restore()
        FreeCAD.closeDocument(self.doc.Name)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def test_torus_cage_command_screenshot_undo_and_bad_cage(self):
        from core.polymesh_io import write_polymesh
        from core.subdivision.sample_cages import torus

        path = os.path.join(self.tmp, "torus.obj")
        write_polymesh(path, torus())
        self.stubs.answer_open_dialog(path)
        FreeCADGui.runCommand("PolyCube_ImportSubD")
        self.assertEqual(self.stubs.boxes, [])
        (obj,) = self.doc.Objects
        shape = obj.Shape
        self.assertTrue(shape.isValid())
        self.assertEqual((len(shape.Solids), len(shape.Faces), len(shape.Shells)), (1, 48, 1))
        self.assertTrue(shape.Shells[0].isClosed())
        # Genus 1: Euler characteristic V - E + F of the B-rep is 0 for a torus.
        self.assertEqual(len(shape.Vertexes) - len(shape.Edges) + len(shape.Faces), 0)
        self.assertIn("Import SubD cage as solid", self.doc.UndoNames)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_torus_solid.png"))
        self.doc.undo()
        self.assertEqual(len(self.doc.Objects), 0)

        bad = os.path.join(self.tmp, "open.obj")
        with open(bad, "w", encoding="utf-8") as handle:
            handle.write("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
        self.stubs.answer_open_dialog(bad)
        FreeCADGui.runCommand("PolyCube_ImportSubD")
        self.assertEqual(len(self.doc.Objects), 0)
        self.assertEqual([kind for kind, _ in self.stubs.boxes], ["warning"])


class WorkflowTest(unittest.TestCase, _ScreenshotAssertions):
    """A new user's session on the bundled cantilever, step by step on one document."""

    @classmethod
    def setUpClass(cls):
        from polycube_wb.preferences import set_default

        FreeCADGui.activateWorkbench(WORKBENCH)
        cls.stubs = _Stubs()
        cls.tmp = tempfile.mkdtemp(prefix="polycube_gui_")
        cls.source = os.path.join(cls.tmp, "cantilever.stl")
        shutil.copy(SAMPLE_MESH, cls.source)
        cls.doc = FreeCAD.newDocument("PolycubeWorkflow")
        set_default("fit_iterations", FIT_ITERATIONS)

    @classmethod
    def tearDownClass(cls):
        from polycube_wb.preferences import reset_defaults

        reset_defaults()
        cls.stubs.restore()
        if FreeCAD.getDocument(cls.doc.Name) is not None:
            FreeCAD.closeDocument(cls.doc.Name)
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def setUp(self):
        self.stubs.boxes.clear()

    def one(self, kind):
        found = _objects(self.doc, kind)
        self.assertEqual(len(found), 1, f"expected one {kind}, found {len(found)}")
        return found[0]

    def open_panel(self, obj):
        """Double-click path: setEdit opens the object's task panel; returns the panel."""
        FreeCADGui.ActiveDocument.setEdit(obj.Name, 0)
        FreeCADGui.updateGui()
        dialog = FreeCADGui.Control.activeDialog()
        self.assertTrue(dialog, f"no task panel open for {obj.Label}")
        from polycube_wb.gui import task_panels

        panel = task_panels.ACTIVE.get(obj.Name)
        self.assertIsNotNone(panel)
        return panel

    def test_1_import_segment_and_label(self):
        self.stubs.answer_open_dialog(self.source)
        FreeCADGui.runCommand("PolyCube_ImportTarget")
        target = self.one("Target")
        self.assertEqual(target.Mesh.CountFacets, 15388)
        self.assertTrue(target.Mesh.isSolid())
        self.assertEqual(target.Status, "ok")
        self.assertIn("Import target mesh", self.doc.UndoNames)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_target_mesh.png"))

        _select(target)
        FreeCADGui.runCommand("PolyCube_SegmentParts")
        parts = self.one("Segmentation")
        self.assertEqual(parts.PartMode, "auto")
        self.assertGreaterEqual(parts.Parts, 1)
        self.assertEqual(len(parts.FaceColors), target.Mesh.CountFacets)
        self.assertFalse(target.ViewObject.Visibility, "the parts supersede the target")
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_parts.png"))
        parts.ViewObject.Visibility = False

        _select(target)
        FreeCADGui.runCommand("PolyCube_LabelPolycube")
        labels = [seg for seg in _objects(self.doc, "Segmentation") if seg is not parts]
        self.assertEqual(len(labels), 1, "labeling does not reuse the automatic parts")
        self.assertEqual(labels[0].PartMode, "single")
        self.assertTrue(labels[0].Valid)
        self.assertEqual(set(labels[0].FaceLabel), set(range(6)))
        self.assertEqual(self.stubs.boxes, [])
        shot = save_screenshot(self.doc, "polycube_labels.png")
        self.assert_screenshot_shows_model(shot)
        self.assertGreater(image_figures(shot)[2], 40, "six label colours and shading")
        from polycube_wb.gui import legend

        self.assertTrue(legend.has_legend(labels[0]), "the labels view shows its colours")
        self.assertFalse(legend.has_legend(parts), "a hidden view has no legend")

    def test_2_base_mesh_fit_and_solid(self):
        FreeCADGui.Selection.clearSelection()
        FreeCADGui.runCommand("PolyCube_BuildBaseMesh")
        base = self.one("BaseMesh")
        self.assertEqual(base.Status, "ok")
        self.assertEqual(base.Segmentation.PartMode, "single",
                         "segment parts does not break the base mesh")
        self.assertGreater(base.Faces, 6)
        # the view provider InitGui.py registered with polycube_wb.view_hook
        self.assertEqual(type(base.ViewObject.Proxy).__name__, "StageViewProvider")
        self.assertEqual(base.ViewObject.LineWidth, 2.0)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_base_mesh.png"),
                                           min_colours=2, min_covered=0.01)
        FreeCADGui.runCommand("PolyCube_FitTarget")
        fit = self.one("Fit")
        self.assertEqual((fit.Status, fit.Iterations), ("ok", FIT_ITERATIONS))
        self.assertFalse(base.ViewObject.Visibility)
        FreeCADGui.runCommand("PolyCube_MakeSolid")
        solid = self.one("Solid")
        self.assertEqual(solid.Cage, fit)
        self.assertTrue(solid.Shape.isValid())
        self.assertEqual(len(solid.Shape.Solids), 1)
        self.assertEqual(self.stubs.boxes, [])
        self.assertIn("Make solid", self.doc.UndoNames)
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_solid.png"))

    def assert_panel_fits(self, panel, kind):
        """No control of the panel is cut off at the Combo View's default width: the task
        view around it has nothing to scroll sideways."""
        from PySide import QtGui

        settled = time.monotonic() + 1.0  # the task box unfolds in an animation
        while time.monotonic() < settled:
            FreeCADGui.updateGui()
            time.sleep(0.05)
        view = panel.form.parentWidget()
        while view is not None and not isinstance(view, QtGui.QScrollArea):
            view = view.parentWidget()
        self.assertIsNotNone(view, f"{kind}: the panel is not in the task view")
        self.assertEqual(view.horizontalScrollBar().maximum(), 0,
                         f"{kind}: the panel is wider than the Combo View")

    def test_3_task_panels_open_and_accept(self):
        from PySide import QtGui

        for kind in ("Target", "Segmentation", "BaseMesh", "Solid"):
            obj = [o for o in _objects(self.doc, kind) if getattr(o, "PartMode", "") != "auto"][0]
            panel = self.open_panel(obj)
            self.assertTrue(panel.widgets)
            self.assert_panel_fits(panel, kind)
            if kind == "Solid":
                self.check_solid_panel_forms(panel)
            panel.accept()
            FreeCADGui.updateGui()
            self.assertFalse(FreeCADGui.Control.activeDialog(), kind)
            self.assertTrue(obj.isValid(), kind)
        fit, solid = self.one("Fit"), self.one("Solid")
        volume = solid.Shape.Volume
        panel = self.open_panel(fit)
        self.assert_panel_fits(panel, "Fit")
        FreeCADGui.getMainWindow().grab().save(os.path.join(OUTPUT, "polycube_fit_panel.png"))
        widget, _ = panel.widgets["Iterations"]
        self.assertIsInstance(widget, QtGui.QSpinBox)
        widget.setValue(FIT_ITERATIONS + 1)
        # a different mode surely moves the surface (from the pulled-inside start, one more
        # inside iteration can leave it where it was)
        mode, _ = panel.widgets["Mode"]
        self.assertIsInstance(mode, QtGui.QComboBox)
        mode.setCurrentIndex(mode.findText("best-fit"))
        self.assertTrue(panel.accept())
        self.assertEqual(fit.Iterations, FIT_ITERATIONS + 1)
        self.assertEqual(fit.Mode, "best-fit")
        self.assertEqual(fit.Status, "ok")
        self.assertNotAlmostEqual(solid.Shape.Volume, volume, places=3,
                                  msg="the solid follows the refit")
        self.assertIn(f"Edit {fit.Label}", self.doc.UndoNames)

    def check_solid_panel_forms(self, panel):
        """One face per block of quads is offered with the G1 patches only (the exporter
        refuses it with the exact form), the grading depth with the exact form only; the
        fields give the property values, whatever the words they show."""
        export, faces = panel.widgets["Export"][0], panel.widgets["Faces"][0]
        depth = panel.widgets["Depth"][0]
        export.setCurrentIndex(export.findData("g1"))
        self.assertTrue(faces.isEnabled())
        self.assertFalse(depth.isEnabled())
        faces.setCurrentIndex(faces.findData("chart"))
        self.assertEqual(faces.currentText(), "one per rectangular block")
        self.assertEqual((panel.values()["Export"], panel.values()["Faces"]), ("g1", "chart"))
        self.assert_panel_fits(panel, "Solid")
        FreeCADGui.getMainWindow().grab().save(os.path.join(OUTPUT, "polycube_solid_panel.png"))
        export.setCurrentIndex(export.findData("exact"))
        self.assertFalse(faces.isEnabled())
        self.assertTrue(depth.isEnabled())
        self.assertEqual((panel.values()["Export"], panel.values()["Faces"]), ("exact", "quad"))

    def test_4_escape_during_the_fit_marks_it_cancelled_and_undo_restores(self):
        fit, solid = self.one("Fit"), self.one("Solid")
        before = (fit.Iterations, list(fit.CageVertices), solid.Shape.Volume,
                  self.doc.UndoCount)
        panel = self.open_panel(fit)
        panel.widgets["Iterations"][0].setValue(400)
        panel.widgets["Convergence"][0].setValue(0.0)  # all 400: far longer than the Esc delay
        mode = panel.widgets["Mode"][0]
        mode.setCurrentIndex(mode.findText("inside"))  # the longer fit (test 3 left best-fit)
        grab = os.path.join(OUTPUT, "polycube_fit_progress.png")
        os.makedirs(OUTPUT, exist_ok=True)
        report_start = len(report_view_text())
        escape = EscapeKey(after=1.5, grab_path=grab)
        started = time.monotonic()
        try:
            accepted = panel.accept()
        finally:
            escape.stop()
        seconds = time.monotonic() - started
        self.assertFalse(accepted, "the panel stays open after a cancel")
        self.assertGreaterEqual(escape.sent, 1)
        self.assertEqual(escape.answered, 0, "Esc cancels without a question")
        self.assertLess(seconds, 60, "cancelled inside the fit, not after 400 iterations")
        self.assertIsNone(panel.outcome)
        self.assertTrue(os.path.isfile(grab))
        # The Fit is marked, keeps its last result, and the step can be undone.
        self.assertEqual(fit.Iterations, 400)
        self.assertEqual(fit.Status, "cancelled by the user")
        self.assertIn("Touched", fit.State)
        self.assertEqual(list(fit.CageVertices), before[1], "no half result")
        self.assertAlmostEqual(solid.Shape.Volume, before[2], places=6)
        self.assertEqual(self.doc.UndoCount, before[3] + 1)
        report = report_view_text()[report_start:]
        self.assertIn(f"Polycube: {fit.Label}: cancelled by the user", report)
        self.assertIn("cancelled by the user at", report)
        self.assertNotIn("Traceback", report)
        self.assertEqual(self.stubs.boxes, [], "a cancel opens no message box")
        _select(fit)
        FreeCADGui.updateGui()
        FreeCADGui.getMainWindow().grab().save(os.path.join(OUTPUT, "polycube_cancelled.png"))
        # It saves and reopens as it is, and reopened it resumes at the Fit.
        copy = os.path.join(self.tmp, "cancelled.FCStd")
        self.doc.saveCopy(copy)
        reopened = FreeCAD.openDocument(copy)
        try:
            fits = _objects(reopened, "Fit")
            self.assertEqual([f.Status for f in fits], ["cancelled by the user"])
            self.assertTrue(fits[0].Proxy.is_stale(fits[0]), "to be run again")
        finally:
            FreeCAD.closeDocument(reopened.Name)
        FreeCAD.setActiveDocument(self.doc.Name)
        panel.reject()
        self.assertFalse(FreeCADGui.Control.activeDialog())
        self.doc.undo()
        self.assertEqual((fit.Iterations, list(fit.CageVertices), solid.Shape.Volume,
                          self.doc.UndoCount), before)
        self.assertTrue(fit.isValid() and solid.isValid())
        self.assertEqual(fit.Status, "ok")
        for obj in (fit, solid):
            self.assertNotIn("Touched", obj.State, obj.Label)
            self.assertNotIn("Invalid", obj.State, obj.Label)

    def test_5_deviation_map(self):
        from polycube_wb.gui import legend

        _select(self.one("Solid"))
        FreeCADGui.runCommand("PolyCube_CheckResult")
        deviation = self.one("Deviation")
        self.assertEqual(deviation.Status, "ok")
        self.assertEqual(len(deviation.VertexColors), deviation.Mesh.CountPoints)
        self.assertTrue(deviation.ViewObject.Coloring)
        shown = [obj.Label for obj in self.doc.Objects
                 if obj.ViewObject.Visibility and obj is not deviation]
        self.assertEqual(shown, [], "the map is shown alone")
        self.assertTrue(legend.has_legend(deviation))
        title, ticks, largest = legend.legend_texts(deviation)
        self.assertEqual(title, "distance to target, mm")
        self.assertIn("outside", ticks[0][1])
        self.assertIn("inside", ticks[-1][1])
        self.assertIn(f"{deviation.MaxDeviation:.3g} mm", largest)
        self.assertGreaterEqual(deviation.ScaleUsed, deviation.MaxDeviation)
        shot = save_screenshot(self.doc, "polycube_deviation.png")
        self.assert_screenshot_shows_model(shot)
        red, blue = _reddish_and_bluish(image_figures(shot)[4])
        self.assertGreater(red + blue, 20, f"no colour map visible ({red} red, {blue} blue)")
        for name, size in (("polycube_deviation_16x9.png", (1600, 900)),
                           ("polycube_deviation_21x9.png", (2100, 900))):
            self.assert_legend_beside_the_model(save_view(self.doc, name, size))
        deviation.ViewObject.Visibility = False
        self.assertFalse(legend.has_legend(deviation), "the legend goes with the map")
        self.one("Solid").ViewObject.Visibility = True

    def assert_legend_beside_the_model(self, path):
        """On FreeCAD's default background, the left edge of the view holds the legend (a
        light panel with the red and blue ends of the bar) and the model is to its right."""
        columns, rows = 160, 60
        width, height, _, _, colours = image_figures(path, columns, rows)
        strip = [colours[y * columns + x] for y in range(rows) for x in range(columns // 10)]
        light = sum(min(rgb >> 16, (rgb >> 8) & 0xFF, rgb & 0xFF) > 215 for rgb in strip)
        red, blue = _reddish_and_bluish(strip)
        self.assertGreater(light, len(strip) // 10, f"{path}: no light legend panel at the left")
        self.assertGreater(red, 0, f"{path}: no red end of the bar at the left")
        self.assertGreater(blue, 0, f"{path}: no blue end of the bar at the left")
        middle = [colours[y * columns + x] for y in range(rows)
                  for x in range(columns // 3, 2 * columns // 3)]
        red, blue = _reddish_and_bluish(middle)
        self.assertGreater(red + blue, 10, f"{path}: no coloured model in the middle")

    def test_6_edit_the_cage_and_undo(self):
        fit, solid = self.one("Fit"), self.one("Solid")
        iterations, before = fit.Iterations, solid.Shape.BoundBox
        volume = solid.Shape.Volume
        points = fit.CageVertices
        top = max(range(len(points)), key=lambda k: points[k].z)
        FreeCADGui.Selection.clearSelection()
        FreeCADGui.Selection.addSelection(self.doc.Name, fit.Name, f"Vertex{top + 1}")
        shown_before = {obj.Name: obj.ViewObject.Visibility for obj in self.doc.Objects}
        panel = self.open_panel(fit)
        self.assertTrue(fit.ViewObject.Visibility, "the cage being edited is shown")
        self.assertTrue(solid.ViewObject.Visibility, "the solid shows the edit's effect")
        self.assertEqual([obj.Label for obj in self.doc.Objects if obj.ViewObject.Visibility
                          and obj not in (fit, solid)], [], "nothing else hides the cage")
        panel.use_selection()
        self.assertEqual(panel.vertex_field.text(), str(top))
        panel.move_fields[2].setValue(8.0)
        panel.move_vertices()
        self.assertEqual(fit.Iterations, iterations)
        self.assertAlmostEqual(fit.CageVertices[top].z, points[top].z + 8.0, places=9)
        self.assertEqual(solid.Status, "ok")
        self.assertGreater(solid.Shape.BoundBox.ZMax, before.ZMax + 1.0,
                           "the solid follows the moved vertex")
        self.assert_screenshot_shows_model(save_screenshot(self.doc, "polycube_edited_cage.png"))
        panel.reject()
        self.assertEqual({obj.Name: obj.ViewObject.Visibility for obj in self.doc.Objects},
                         shown_before, "closing the panel shows what was shown before")
        self.doc.undo()
        self.assertAlmostEqual(fit.CageVertices[top].z, points[top].z, places=9)
        # the solid is the one before the edit: same volume (its bounding box can differ by
        # ~1e-3 mm, depending on whether OpenCascade boxes the displayed triangulation or poles)
        self.assertAlmostEqual(solid.Shape.Volume / volume, 1.0, places=9)

    def test_7_save_reopen_without_the_source_and_recompute(self):
        from polycube_wb import api

        os.remove(self.source)
        path = os.path.join(self.tmp, "workflow.FCStd")
        self.doc.saveAs(path)
        name = self.doc.Name
        FreeCAD.closeDocument(name)
        type(self).doc = FreeCAD.openDocument(path)
        from polycube_wb.gui import legend

        fit, solid, deviation = self.one("Fit"), self.one("Solid"), self.one("Deviation")
        self.assertTrue(solid.Shape.isValid())
        deviation.ViewObject.Visibility = True
        self.assertTrue(legend.has_legend(deviation), "the reopened map shows its legend")
        deviation.ViewObject.Visibility = False
        panel = self.open_panel(fit)
        panel.widgets["Iterations"][0].setValue(1)
        self.assertTrue(panel.accept())
        self.assertEqual((fit.Status, solid.Status), ("ok", "ok"))
        # A property edited in the property editor, then the workbench's recompute.
        solid.Depth = 6
        FreeCADGui.runCommand("PolyCube_Recompute")
        self.assertEqual(self.stubs.boxes, [])
        self.assertEqual(solid.Status, "ok")
        self.assertTrue(solid.isValid() and "Touched" not in solid.State, solid.State)
        self.assertIn("Recompute", self.doc.UndoNames)
        step = api.export_step(solid, os.path.join(self.tmp, "cantilever.step"))
        import Part

        read = Part.read(step)
        self.assertEqual(len(read.Solids), 1)
        self.assertAlmostEqual(read.Volume / solid.Shape.Volume, 1.0, places=6)


class ReconstructAllTest(unittest.TestCase, _ScreenshotAssertions):
    """Reconstruct all on the selected target: one undo step, success reported."""

    def test_reconstruct_all_uses_the_selected_target(self):
        from polycube_wb import api
        from polycube_wb.preferences import reset_defaults, set_default

        stubs = _Stubs()
        doc = FreeCAD.newDocument("PolycubeReconstructAll")
        FreeCADGui.activateWorkbench(WORKBENCH)
        set_default("fit_iterations", FIT_ITERATIONS)
        try:
            first = api.make_target(doc, SAMPLE_MESH, name="first",
                                    check_self_intersections=False)
            second = api.make_target(doc, SAMPLE_MESH, name="second",
                                     check_self_intersections=False)
            doc.recompute()
            stubs.answer_open_dialog(None)
            _select(first)
            FreeCADGui.runCommand("PolyCube_ReconstructAll")
            self.assertEqual(stubs.boxes, [])
            (solid,) = _objects(doc, "Solid")
            self.assertIs(api.upstream_objects(solid)["Target"], first)
            self.assertEqual(second.InList, [])
            self.assertTrue(solid.Shape.isValid())
            self.assertEqual(len(_objects(doc, "Target")), 2, "no second import")
            status = FreeCADGui.getMainWindow().statusBar().currentMessage()
            self.assertIn("B-spline faces", status)
            self.assert_screenshot_shows_model(save_screenshot(doc, "polycube_reconstructed.png"))
            self.assertEqual(doc.UndoNames[0], "Reconstruct all")
            doc.undo()
            self.assertEqual(len(doc.Objects), 2)
        finally:
            reset_defaults()
            stubs.restore()
            FreeCAD.closeDocument(doc.Name)


class EntryPointTest(unittest.TestCase):
    """The GUI gives the command line's result: the same fitted base-mesh bytes and a
    solid with the poles and volume of the command line's STEP solid (``BoundBox`` values
    are not compared: the box of a displayed, hence tessellated, shape comes
    from its triangulation, so it is no measure of the geometry and is not compared)."""

    FIT = 3
    TOLERANCE = 1e-9
    """Relative to the diagonal (poles) or to the volume: STEP text and OpenCascade round-off."""

    def test_gui_gives_the_command_line_base_mesh_and_solid(self):
        import numpy as np
        import Part

        from polycube_wb import api

        python = os.path.join(REPO, ".venv", "bin", "python")
        if not os.path.isfile(python):
            self.skipTest("no .venv to run the command line with (make setup)")
        tmp = tempfile.mkdtemp(prefix="polycube_entry_")
        doc = FreeCAD.newDocument("PolycubeEntryPoints")
        try:
            paths = {name: os.path.join(tmp, name) for name in ("cli.obj", "cli.step", "gui.obj")}
            done = subprocess.run([python, "-m", "polycube_wb", "reconstruct", SAMPLE_MESH,
                                   "--fit-iterations", str(self.FIT), "-o", paths["cli.step"],
                                   "--base-mesh", paths["cli.obj"]], cwd=REPO,
                                  capture_output=True, text=True, timeout=900)
            self.assertEqual(done.returncode, 0, done.stderr)
            api.reconstruct_to_step(SAMPLE_MESH, None, paths["gui.obj"], None, None, "fit",
                                    fit_iterations=self.FIT)
            with open(paths["cli.obj"], "rb") as cli, open(paths["gui.obj"], "rb") as gui:
                self.assertEqual(cli.read(), gui.read(), "the base meshes differ")
            solid = api.reconstruct(doc, SAMPLE_MESH, fit_iterations=self.FIT).Shape
            FreeCADGui.updateGui()
            step = Part.read(paths["cli.step"])

            def poles(shape):
                return np.array(sorted(tuple(p) for face in shape.Faces
                                       for row in face.Surface.getPoles() for p in row))

            gap = np.abs(poles(solid) - poles(step)).max()
            self.assertLessEqual(gap, self.TOLERANCE * step.BoundBox.DiagonalLength)
            self.assertLessEqual(abs(solid.Volume - step.Volume), self.TOLERANCE * step.Volume)
        finally:
            FreeCAD.closeDocument(doc.Name)
            shutil.rmtree(tmp, ignore_errors=True)


FUZZ_COMMANDS = (("PolyCube_ImportTarget", "Import target mesh"),
                 ("PolyCube_ReconstructAll", "Reconstruct all"))


def _fuzz_meshes():
    folder = os.path.join(REPO, "tests", "fuzz")
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import fuzz_meshes

    return fuzz_meshes


def bad_files(folder):
    """``[(path, a word the message must contain)]`` of the bad inputs, written into ``folder``."""
    meshes = _fuzz_meshes()
    box = meshes.box()
    files = {
        "truncated.stl": (meshes.binary_stl(box)[:200], "truncated"),
        "bad_index.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 9\nf 0 3 4\n",
                          "index"),
        "nan.stl": (meshes.binary_stl(meshes.with_vertex(box, 0, float("nan"))), "nan"),
        "huge.stl": (meshes.binary_stl(meshes.with_vertex(box, 0, 1e30)), "coordinate"),
        "not_a_mesh.stl": (b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, "stl"),
    }
    found = []
    for name, (data, word) in files.items():
        path = os.path.join(folder, name)
        with open(path, "wb") as handle:
            handle.write(data)
        found.append((path, word))
    directory = os.path.join(folder, "a_folder.stl")
    os.mkdir(directory)
    found.append((directory, "folder"))
    return found


class BadFilesThroughCommandsTest(unittest.TestCase):
    """A few cases of the fuzz corpus (``tests/fuzz/fuzz_meshes.py``: a truncated binary STL,
    an OBJ with out-of-range and zero indices, NaN and 1e30 coordinates, a file that is no
    mesh, a folder) through *Import target mesh* and *Reconstruct all* on an empty document:
    one warning box and one Report-view line ``Polycube: <command>: <what is wrong>`` naming
    the file, no traceback, no object in the document (none with a half result), nothing to
    undo."""

    def setUp(self):
        FreeCADGui.activateWorkbench(WORKBENCH)
        self.stubs = _Stubs()
        self.tmp = tempfile.mkdtemp(prefix="polycube_gui_fuzz_")

    def tearDown(self):
        self.stubs.restore()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def test_bad_files_give_a_message_and_leave_no_object(self):
        cases = bad_files(self.tmp)
        for command, title in FUZZ_COMMANDS:
            for path, word in cases:
                with self.subTest(command=command, file=os.path.basename(path)):
                    self._check_one(command, title, path, word)

    def _check_one(self, command, title, path, word):
        doc = FreeCAD.newDocument("PolycubeFuzz")
        doc.UndoMode = 1
        try:
            self.stubs.boxes.clear()
            self.stubs.answer_open_dialog(path)
            before = len(report_view_text())
            FreeCADGui.runCommand(command)
            FreeCADGui.updateGui()
            report = report_view_text()[before:]
            self.assertEqual(doc.Objects, [], "no object, so none with a half result")
            self.assertEqual(doc.UndoCount, 0, "nothing to undo")
            self.assertEqual(len(self.stubs.boxes), 1, self.stubs.boxes)
            kind, text = self.stubs.boxes[0]
            self.assertEqual(kind, "warning")
            self.assertIn(word, text.lower())
            self.assertIn(os.path.basename(path), text, "the message names the file")
            lines = [line[line.index("Polycube:"):] for line in report.splitlines()
                     if "Polycube:" in line]  # after the Report view's time stamp
            self.assertEqual(lines, [f"Polycube: {title}: {text}"], report)
            self.assertNotIn("Traceback", report)
        finally:
            FreeCAD.closeDocument(doc.Name)

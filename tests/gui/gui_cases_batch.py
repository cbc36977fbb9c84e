# SPDX-License-Identifier: LGPL-2.1-or-later
"""*Reconstruct folder* in the real FreeCAD GUI (loaded by TestPolycubeGui.py).

The folder dialogs and the browser are stubbed; the batch itself is the real command-line
batch in its own processes, on a folder with the tiny level-set cantilever (a dev mesh)
and a broken file. One case lets it finish (the summary is opened, the dialog closes, the
Report view's lines are the rows), the other presses a real Esc key while the cantilever
runs (the batch and its meshes stop on SIGINT, the finished mesh keeps its outputs). A grab of
the screen with the dialog goes to ``$POLYCUBE_GUI_OUTPUT`` (default ``tests/gui/output/``).
"""
import csv
import os
import shutil
import tempfile
import time
import unittest

import FreeCAD
import FreeCADGui

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUTPUT = os.environ.get("POLYCUBE_GUI_OUTPUT") or os.path.join(REPO, "tests", "gui", "output")
TINY = os.path.join(REPO, "..", "shared", "data", "meshes", "to_levelset_cantilever_tiny.stl")
WORKBENCH = "PolycubeWorkbench"
COMMAND = "PolyCube_ReconstructFolder"
GUARD_SECONDS = 300.0
"""Guard against a batch that never ends (not a timing check)."""


def _process_events_until(condition, guard=GUARD_SECONDS):
    from PySide import QtGui

    started = time.monotonic()
    while not condition():
        if time.monotonic() - started > guard:
            raise AssertionError(f"still waiting after {guard:g} s")
        QtGui.QApplication.processEvents()
        time.sleep(0.02)


def _batch_dialog():
    from PySide import QtGui

    dialogs = [w for w in QtGui.QApplication.topLevelWidgets()
               if isinstance(w, QtGui.QDialog) and w.windowTitle() == "Reconstruct folder"
               and w.isVisible()]
    return dialogs[-1] if dialogs else None


def _live_members(group):
    """Processes of process group ``group`` that are not zombies (Linux /proc)."""
    live = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as handle:
                fields = handle.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == group and fields[0] != "Z":
            live.append(int(entry))
    return live


class ReconstructFolderTest(unittest.TestCase):
    """The batch in the background from the GUI: progress, summary, Esc."""

    def setUp(self):
        from polycube_wb.gui import batch_command
        from polycube_wb.preferences import set_default

        if not os.path.exists(TINY):
            self.skipTest("dev mesh to_levelset_cantilever_tiny.stl not available")
        FreeCADGui.activateWorkbench(WORKBENCH)
        self.module = batch_command
        self.saved = (batch_command.ask_folder, batch_command.open_summary)
        self.tmp = tempfile.mkdtemp(prefix="polycube_gui_batch_")
        self.folder = os.path.join(self.tmp, "meshes")
        os.mkdir(self.folder)
        shutil.copy(TINY, os.path.join(self.folder, "tiny.stl"))
        with open(os.path.join(self.folder, "broken.stl"), "w") as handle:
            handle.write("solid broken\nendsolid broken\n")
        self.out = os.path.join(self.tmp, "out")
        answers = [self.folder, self.out]
        batch_command.ask_folder = lambda title, start: answers.pop(0)
        self.opened = []
        batch_command.open_summary = self.opened.append
        set_default("fit_iterations", 2)
        set_default("target_faces", 60)

    def tearDown(self):
        from polycube_wb.preferences import reset_defaults

        self.module.ask_folder, self.module.open_summary = self.saved
        reset_defaults()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def start(self):
        FreeCADGui.runCommand(COMMAND)
        dialog = _batch_dialog()
        self.assertIsNotNone(dialog, "the progress dialog is shown")
        self.assertFalse(dialog.isModal(), "FreeCAD stays usable while the batch runs")
        self.assertIsNone(dialog.run.process.poll(), "the command returns while the batch runs")
        self.assertFalse(FreeCADGui.Command.get(COMMAND).isActive(), "one batch at a time")
        return dialog

    def test_folder_runs_in_the_background_and_opens_the_summary(self):
        from PySide import QtGui

        dialog = self.start()
        run = dialog.run
        self.assertIn("--progress-lines", run.command)
        self.assertEqual(run.command[run.command.index("--fit-iterations") + 1], "2")
        _process_events_until(lambda: run.progress["done"] >= 1 or dialog.finished_run)
        QtGui.QApplication.processEvents()
        os.makedirs(OUTPUT, exist_ok=True)
        grab = os.path.join(OUTPUT, "polycube_batch_progress.png")
        QtGui.QApplication.primaryScreen().grabWindow(0).save(grab)
        if not dialog.finished_run:
            self.assertEqual(dialog.bar.maximum(), 2)
            self.assertIn("of 2 meshes done", dialog.counts.text())
        _process_events_until(lambda: dialog.finished_run)
        self.assertFalse(dialog.isVisible())
        summary = os.path.join(self.out, "summary.html")
        self.assertEqual(self.opened, [summary])
        with open(os.path.join(self.out, "summary.csv"), newline="") as handle:
            rows = {row["name"]: row for row in csv.DictReader(handle)}
        self.assertEqual((rows["tiny"]["status"], rows["broken"]["status"]), ("ok", "failed"))
        self.assertEqual(rows["broken"]["failed_stage"], "intake")
        self.assertGreater(os.path.getsize(os.path.join(self.out, "tiny.step")), 0)
        self.assertEqual(sorted(m["name"] for m in run.meshes), ["broken", "tiny"])
        status = FreeCADGui.getMainWindow().statusBar().currentMessage()
        self.assertIn("2 meshes, 1 solids, 1 failed", status)
        self.assertTrue(FreeCADGui.Command.get(COMMAND).isActive())

    def test_escape_kills_the_batch_and_keeps_the_finished_mesh(self):
        from PySide import QtCore, QtGui

        dialog = self.start()
        run = dialog.run
        _process_events_until(lambda: any(m["name"] == "broken" for m in run.meshes)
                              or dialog.finished_run)
        self.assertFalse(dialog.finished_run, "the cantilever is still running")
        group = run.process.pid
        self.assertGreater(len(_live_members(group)), 1, "the batch runs a mesh process")
        dialog.activateWindow()
        for kind in (QtCore.QEvent.KeyPress, QtCore.QEvent.KeyRelease):
            QtGui.QApplication.postEvent(dialog, QtGui.QKeyEvent(kind, QtCore.Qt.Key_Escape,
                                                                  QtCore.Qt.NoModifier))
        _process_events_until(lambda: dialog.finished_run, guard=30.0)
        self.assertTrue(run.cancelled)
        self.assertEqual(run.process.returncode, 130, "stopped by SIGINT (Ctrl-C), not killed")
        _process_events_until(lambda: not _live_members(group), guard=10.0)
        self.assertTrue(os.path.isfile(os.path.join(self.out, "broken.json")))
        left = [name for name in os.listdir(self.out) if name.startswith(("tiny", ".tiny"))]
        self.assertEqual(left, [], "the stopped mesh leaves no output, report or temporary file")
        self.assertFalse(os.path.exists(os.path.join(self.out, "summary.html")))
        self.assertEqual(self.opened, [])
        self.assertFalse(dialog.isVisible())

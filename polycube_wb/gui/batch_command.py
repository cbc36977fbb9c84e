# SPDX-License-Identifier: LGPL-2.1-or-later
"""*Reconstruct folder*: the command-line batch over a folder of meshes, run from the GUI.

The batch (``python -m polycube_wb batch FOLDER -o OUT --progress-lines``, every mesh in
its own process) runs as a child process in a session of its own, so FreeCAD stays
responsive: a Qt timer reads its ``PROGRESS`` / ``MESH`` lines (``polycube_wb.batch_progress``)
from a reader thread and moves a non-modal dialog's progress bar. Cancel (the button or
Esc) sends the batch's whole process group SIGINT, as Ctrl-C in a terminal does: the
running meshes stop and remove their temporary files, the batch exits 130 without a summary
(a group still running after ``CANCEL_GRACE_SECONDS`` is killed); meshes already
finished keep their outputs and are skipped when the same folder is run again. When the
batch ends, the Report view gets one line per mesh and the totals, and ``summary.html`` is
opened in the desktop's browser. The pipeline parameters are the user's preferences.
"""
import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading

import FreeCAD
import FreeCADGui

from polycube_wb import ADDON_DIR
from polycube_wb.gui import icon_path

POLL_MS = 100
CANCEL_GRACE_SECONDS = 10.0
"""How long a cancelled batch may take to stop after SIGINT before it is killed."""
"""How often the dialog reads the batch's output."""
OUTPUT_FOLDER = "polycube_batch"
"""Default output folder, inside the chosen mesh folder."""


# ----------------------------------------------------------------------------------------
# Dialogs and the browser (tests replace ask_folder and open_summary)
# ----------------------------------------------------------------------------------------

def ask_folder(title, start):
    """Folder dialog; returns the chosen folder or None."""
    from PySide import QtGui

    path = QtGui.QFileDialog.getExistingDirectory(FreeCADGui.getMainWindow(), title, start)
    return path or None


def _ask_output_folder(folder):
    """Folder dialog for the output, proposing ``folder/OUTPUT_FOLDER`` (made first, as the
    dialog only offers folders that exist; removed again while empty when another is chosen
    or the dialog is cancelled). Returns the chosen folder or None."""
    suggested = os.path.join(folder, OUTPUT_FOLDER)
    made = False
    if not os.path.isdir(suggested):
        try:
            os.makedirs(suggested)
            made = True
        except OSError:  # a read-only mesh folder: the dialog starts in it
            pass
    chosen = ask_folder("Reconstruct folder: the output folder",
                        suggested if os.path.isdir(suggested) else folder)
    if made and (chosen is None or os.path.realpath(chosen) != os.path.realpath(suggested)):
        try:
            os.rmdir(suggested)  # only while empty
        except OSError:
            pass
    return chosen


def open_summary(path):
    """Open ``summary.html`` in the desktop's browser."""
    from PySide import QtCore, QtGui

    QtGui.QDesktopServices.openUrl(QtCore.QUrl.fromLocalFile(path))


# ----------------------------------------------------------------------------------------
# The batch process
# ----------------------------------------------------------------------------------------

def batch_interpreter():
    """``(python, env)`` that run the command-line batch outside FreeCAD's own process.

    The project's ``.venv`` interpreter when it exists (``make setup``); else the system
    ``python3.X`` of FreeCAD's Python version with FreeCAD's module folder, the user's
    ``AdditionalPythonPackages`` and this addon on ``PYTHONPATH``.

    Raises
    ------
    RuntimeError
        No such interpreter is found (the message says what to install).
    """
    env = dict(os.environ)
    venv = os.path.join(ADDON_DIR, ".venv", "bin", "python")
    if os.path.isfile(venv):
        return venv, env
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    python = shutil.which(version)
    if python is None:
        raise RuntimeError(f"Reconstruct folder runs the batch with {version}, which is not on "
                           f"the PATH; install it or run 'make setup' in {ADDON_DIR}")
    packages = os.path.join(FreeCAD.getUserAppDataDir(), "AdditionalPythonPackages")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [
        os.path.dirname(FreeCAD.__file__), packages, ADDON_DIR, env.get("PYTHONPATH")]))
    return python, env


def batch_arguments(folder, out_dir):
    """The batch's command-line arguments for ``folder`` -> ``out_dir``, with the user's
    preferences (``polycube_wb.preferences``) as pipeline options."""
    from polycube_wb.preferences import PREFERENCE_FIELDS, default

    args = ["-m", "polycube_wb", "batch", folder, "-o", out_dir, "--progress-lines"]
    for name in PREFERENCE_FIELDS:
        value = default(name)
        if name == "repair":
            args += [] if value else ["--no-repair"]
        else:
            args += [f"--{name.replace('_', '-')}", str(value)]
    return args


class BatchRun:
    """The batch as a child process in its own session, read line by line.

    Parameters
    ----------
    folder, out_dir : the mesh folder and the output folder.
    """

    def __init__(self, folder, out_dir):
        from polycube_wb.batch_progress import MESH_PREFIX, PROGRESS_PREFIX

        self.prefixes = (PROGRESS_PREFIX, MESH_PREFIX)
        self.folder, self.out_dir = folder, out_dir
        python, env = batch_interpreter()
        self.command = [python] + batch_arguments(folder, out_dir)
        self.lines = queue.Queue()
        self.progress = {"done": 0, "failed": 0, "running": 0, "total": 0}
        self.meshes = []
        self.other = []
        self.cancelled = False
        self.process = subprocess.Popen(self.command, cwd=ADDON_DIR, env=env,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True, start_new_session=True)
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def poll(self):
        """Take the lines read so far; returns True while the batch runs (or output is left)."""
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                return True
            if line is None:
                self.process.wait()
                return False
            if line.startswith(self.prefixes[0]):
                self.progress = json.loads(line[len(self.prefixes[0]):])
            elif line.startswith(self.prefixes[1]):
                self.meshes.append(json.loads(line[len(self.prefixes[1]):]))
            elif line.strip():
                self.other.append(line)

    def cancel(self):
        """Stop the batch and the meshes it runs (its whole process group): SIGINT, then
        SIGKILL if it still runs after ``CANCEL_GRACE_SECONDS``."""
        self.cancelled = True
        for stop in (signal.SIGINT, signal.SIGKILL):
            if self.process.poll() is not None:
                return
            try:
                os.killpg(self.process.pid, stop)
            except ProcessLookupError:
                pass
            try:
                self.process.wait(timeout=CANCEL_GRACE_SECONDS)
            except subprocess.TimeoutExpired:
                continue

    @property
    def summary_html(self):
        return os.path.join(self.out_dir, "summary.html")


# ----------------------------------------------------------------------------------------
# The dialog and the command
# ----------------------------------------------------------------------------------------

def _dialog_class():
    from PySide import QtCore, QtGui

    class BatchDialog(QtGui.QDialog):
        """Non-modal progress of a :class:`BatchRun`: a bar, the counts, Cancel (or Esc)."""

        def __init__(self, run):
            super().__init__(FreeCADGui.getMainWindow())
            self.run = run
            self.finished_run = False
            self.setWindowTitle("Reconstruct folder")
            self.setModal(False)
            layout = QtGui.QVBoxLayout(self)
            layout.addWidget(QtGui.QLabel(f"{run.folder}\n-> {run.out_dir}"))
            self.bar = QtGui.QProgressBar()
            self.bar.setRange(0, 0)
            layout.addWidget(self.bar)
            self.counts = QtGui.QLabel("starting the batch...")
            layout.addWidget(self.counts)
            self.last = QtGui.QLabel("")
            layout.addWidget(self.last)
            self.cancel_button = QtGui.QPushButton("Cancel")
            self.cancel_button.clicked.connect(self.reject)
            layout.addWidget(self.cancel_button)
            self.resize(520, 160)
            self.timer = QtCore.QTimer(self)
            self.timer.setInterval(POLL_MS)
            self.timer.timeout.connect(self.tick)
            self.timer.start()

        def tick(self):
            running = self.run.poll()
            counts = self.run.progress
            if counts["total"]:
                self.bar.setRange(0, counts["total"])
                self.bar.setValue(counts["done"])
                self.counts.setText(f"{counts['done']} of {counts['total']} meshes done, "
                                    f"{counts['failed']} failed, {counts['running']} running")
            if self.run.meshes:
                mesh = self.run.meshes[-1]
                self.last.setText(f"last: {mesh['name']}: {mesh['status']}")
            if not running:
                self.timer.stop()
                self.finished_run = True
                _report_end(self.run)
                self.accept()

        def reject(self):
            """Cancel or Esc: kill the batch, keep what finished, close."""
            if not self.finished_run:
                self.timer.stop()
                self.run.cancel()
                self.run.poll()
                self.finished_run = True
                _report_cancel(self.run)
            super().reject()

    return BatchDialog


def _report_end(run):
    """Report view lines of a finished batch; opens its summary page."""
    for mesh in run.meshes:
        if mesh["status"] == "ok":
            FreeCAD.Console.PrintMessage(f"Polycube: {mesh['name']}: solid"
                                         f"{' (up to date)' if mesh['skipped'] else ''}\n")
        else:
            FreeCAD.Console.PrintWarning(f"Polycube: {mesh['name']}: {mesh['status']} at "
                                         f"{mesh['failed_stage'] or '-'}: {mesh['message']}\n")
    if run.process.returncode != 0 or not os.path.isfile(run.summary_html):
        tail = "\n".join(run.other[-5:]) or "no output"
        FreeCAD.Console.PrintError(f"Polycube: Reconstruct folder: the batch exited with code "
                                   f"{run.process.returncode}:\n{tail}\n")
        from polycube_wb.gui.dialogs import message_box

        message_box("warning", "Reconstruct folder", tail)
        return
    failed = sum(mesh["status"] != "ok" for mesh in run.meshes)
    text = (f"Reconstruct folder: {len(run.meshes)} meshes, {len(run.meshes) - failed} "
            f"solids, {failed} failed; summary {run.summary_html}")
    FreeCAD.Console.PrintMessage(f"Polycube: {text}\n")
    FreeCADGui.getMainWindow().statusBar().showMessage(f"Polycube: {text}", 15000)
    open_summary(run.summary_html)


def _report_cancel(run):
    done = len(run.meshes)
    FreeCAD.Console.PrintWarning(
        f"Polycube: Reconstruct folder cancelled after {done} of {run.progress['total'] or '?'}"
        f" meshes; their outputs stay in {run.out_dir} and are skipped when the folder is "
        f"run again\n")


class ReconstructFolderCommand:
    """Menu and toolbar command (``PolyCube_ReconstructFolder``)."""

    ID = "PolyCube_ReconstructFolder"
    MENU_TEXT = "Reconstruct folder..."
    TOOLTIP = ("Reconstruct every mesh of a folder in the background (the command-line batch, "
               "one process per mesh) with your preferences; opens the summary page when done")

    def __init__(self):
        self.dialog = None

    def GetResources(self):
        return {"Pixmap": icon_path(self.ID), "MenuText": self.MENU_TEXT,
                "ToolTip": self.TOOLTIP}

    def IsActive(self):
        return self.dialog is None or self.dialog.finished_run

    def Activated(self):
        from polycube_wb.gui.dialogs import last_directory, message_box

        folder = ask_folder("Reconstruct folder: the meshes", last_directory())
        if folder is None:
            return
        out_dir = _ask_output_folder(folder)
        if out_dir is None:
            return
        try:
            run = BatchRun(folder, out_dir)
        except (RuntimeError, OSError) as exc:
            FreeCAD.Console.PrintError(f"Polycube: Reconstruct folder: {exc}\n")
            message_box("critical", "Reconstruct folder", str(exc))
            return
        FreeCAD.Console.PrintMessage(f"Polycube: Reconstruct folder: {folder} -> {out_dir}\n")
        FreeCAD.Console.PrintLog(f"Polycube: {' '.join(run.command)}\n")
        self.dialog = _dialog_class()(run)
        self.dialog.show()

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Stage computations off FreeCAD's GUI thread while its event loop keeps running.

A job (:class:`polycube_wb.stage_jobs.StageJob`) runs in the GUI's stage process
(:mod:`polycube_wb.stage_worker`, started at the first job and kept), so that no
computation can hold up the event loop, whatever it does with Python's GIL (OpenCascade
shapes go there and back in OpenCascade's binary format); a job that needs FreeCAD's own objects
(``needs_freecad``) runs in a worker thread of FreeCAD itself. Either
way the GUI thread waits in a nested ``QEventLoop`` (as a modal dialog does), which
repaints the window, lets the user turn and zoom the 3D view and answers Esc, while a
``QTimer`` moves the progress bar from what the stage reports.

:class:`GuiProgress` is the progress of one command: a bar with a *Cancel* button in the
status bar, the stage in the status-bar message, a busy cursor, and an input guard that
turns Esc into a cancel and keeps every other click and key away from FreeCAD meanwhile
(only the 3D view's navigation and the *Cancel* button stay live), so the document cannot
change under a running stage. :func:`run_job` runs one job with it.

A cancel ends the stage process at once (the next job starts a new one). A worker thread
is told twice: its progress raises ``Cancelled`` at the stage's next report, and
``Cancelled`` is raised asynchronously in the thread at its next Python instruction
(``PyThreadState_SetAsyncExc``); one still inside a long compiled call after
:data:`CANCEL_GRACE_SECONDS` is left to end alone (its result is dropped), and the next
job waits for it first.
"""
import atexit
import ctypes
import os
import queue
import signal
import subprocess
import threading
import time

import FreeCAD
import FreeCADGui

from core.errors import Cancelled
from core.progress import Progress

POLL_MS = 25
"""How often the GUI thread looks at the worker (progress, end, cancel)."""
CANCEL_GRACE_SECONDS = 0.3
"""How long a cancelled job may take to stop before the GUI goes on without it."""
STEPS = 1000
"""Resolution of the progress bar."""
_LEFT_RUNNING = []
"""Cancelled worker threads that had not stopped within the grace time."""


class WorkerProgress(Progress):
    """The worker thread's progress: keeps the latest report for the GUI thread to show,
    raises ``Cancelled`` once the GUI thread asked to stop."""

    def __init__(self):
        self.latest = None
        self.stop = threading.Event()

    def report(self, stage, fraction, message=""):
        self.check_cancel()
        self.latest = (stage, fraction, message)

    def check_cancel(self):
        if self.stop.is_set():
            raise Cancelled("cancelled by the user")


def run_job(job, progress):
    """Run ``job`` (a ``StageJob``) in the stage process, or in a worker thread when it needs
    FreeCAD; the GUI stays live meanwhile. Returns what the job returned; the shapes it
    returned (alone or in a tuple) are triangulated for the 3D view first
    (:func:`polycube_wb.gui.display_tessellation.triangulate_for_display`), so that setting
    them on a shown object does not hold up the event loop.

    Raises
    ------
    Cancelled
        The user cancelled; nothing of the computation is returned.
    Exception
        What the job raised, raised again in the GUI thread.
    """
    if not job.needs_freecad:
        from polycube_wb.stage_jobs import register_shape_pickling

        register_shape_pickling()
        try:
            stage_process()
        except RuntimeError as exc:  # no interpreter for the process: FreeCAD's own thread
            FreeCAD.Console.PrintLog(f"Polycube: {exc}; the stage runs in a thread\n")
        else:
            return _triangulated(run_in_process(job, progress), progress)
    return _triangulated(run_in_thread(job, progress), progress)


def _triangulated(result, progress):
    """``result``, its shapes (``result`` itself or the items of a tuple) triangulated for
    display."""
    import Part

    from polycube_wb.gui.display_tessellation import triangulate_for_display

    for item in result if isinstance(result, tuple) else (result,):
        if isinstance(item, Part.Shape) and not item.isNull():
            progress.report("preparing the display", 1.0)
            triangulate_for_display(item, progress)
    return result


def run_in_thread(compute, progress):
    """Run ``compute(worker_progress)`` in a worker thread; the GUI stays live meanwhile.

    Parameters
    ----------
    compute : callable taking a ``core.progress.Progress``; touches no FreeCAD object.
    progress : ``core.progress.Progress`` of the GUI thread (a :class:`GuiProgress` or a
        share of it); the worker's reports are passed to it, and its ``check_cancel``
        raising ``Cancelled`` (Esc, *Cancel*) stops the worker.

    Returns
    -------
    What ``compute`` returned.

    Raises
    ------
    Cancelled
        The user cancelled; nothing of the computation is returned.
    Exception
        What ``compute`` raised, raised again in the GUI thread.
    """
    from PySide import QtCore

    _wait_for_left_running(progress)
    worker = WorkerProgress()
    outcome = {}

    def work():
        try:
            outcome["result"] = compute(worker)
        except BaseException as exc:  # handed to the GUI thread, raised there
            outcome["error"] = exc

    thread = threading.Thread(target=work, name="polycube-stage", daemon=True)
    thread.start()
    loop = QtCore.QEventLoop()
    cancelled_at = None
    shown = None

    def poll():
        nonlocal cancelled_at, shown
        if cancelled_at is None:
            try:
                latest = worker.latest
                if latest is not None and latest != shown:
                    shown = latest
                    progress.report(*latest)
                progress.check_cancel()
            except Cancelled:
                cancelled_at = time.monotonic()
                worker.stop.set()
                _raise_in_thread(thread, outcome)
        if not thread.is_alive():
            loop.quit()
        elif cancelled_at is not None and \
                time.monotonic() - cancelled_at > CANCEL_GRACE_SECONDS:
            _LEFT_RUNNING.append(thread)
            loop.quit()

    timer = QtCore.QTimer()
    timer.setInterval(POLL_MS)
    timer.timeout.connect(poll)
    timer.start()
    try:
        if thread.is_alive():
            loop.exec_()
    finally:
        timer.stop()
    if cancelled_at is not None:
        raise Cancelled("cancelled by the user")
    if "error" in outcome:
        raise outcome["error"]
    return outcome["result"]


class StageProcess:
    """The stage process (:mod:`polycube_wb.stage_worker`) and a thread reading its frames."""

    def __init__(self):
        from polycube_wb import ADDON_DIR
        from polycube_wb.gui.batch_command import batch_interpreter

        python, env = batch_interpreter()
        self.process = subprocess.Popen([python, "-m", "polycube_wb.stage_worker"],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        cwd=ADDON_DIR, env=env, start_new_session=True)
        self.frames = queue.Queue()
        threading.Thread(target=self._read, name="polycube-stage-reader", daemon=True).start()

    def _read(self):
        from polycube_wb.stage_worker import read_frame

        while True:
            try:
                self.frames.put(read_frame(self.process.stdout))
            except Exception as exc:  # the process ended (or sent what cannot be read)
                self.frames.put(("ended", exc))
                return

    def send(self, job):
        """Hand ``job`` to the process from a thread of its own: pickling a stage's inputs
        and pushing them through the pipe (as fast as the process reads) would hold up the
        event loop; a failure to send is a frame ``("ended", exception)``."""
        from polycube_wb.stage_worker import write_frame

        def write():
            try:
                write_frame(self.process.stdin, (job.function, job.args))
            except Exception as exc:  # the process ended (or the job does not pickle)
                self.frames.put(("ended", exc))

        threading.Thread(target=write, name="polycube-stage-writer", daemon=True).start()

    def alive(self):
        return self.process.poll() is None

    def end(self):
        """End the process at once (its group: anything it started too)."""
        if self.alive():
            try:
                os.killpg(self.process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.process.wait()
        for stream in (self.process.stdin, self.process.stdout):
            try:
                stream.close()
            except OSError:
                pass


_PROCESS = None
atexit.register(lambda: end_stage_process())


def stage_process():
    """The running stage process (started when there is none)."""
    global _PROCESS
    if _PROCESS is None or not _PROCESS.alive():
        _PROCESS = StageProcess()
    return _PROCESS


def end_stage_process():
    """End the stage process (a cancel; FreeCAD closing)."""
    global _PROCESS
    if _PROCESS is not None:
        _PROCESS.end()
        _PROCESS = None
atexit.register(lambda: end_stage_process())


def run_in_process(job, progress):
    """Run ``job`` in the stage process; the GUI stays live meanwhile (see :func:`run_job`)."""
    from PySide import QtCore

    from polycube_wb.stage_jobs import StageFailed
    from polycube_wb.stage_jobs import RebuiltError

    worker = stage_process()
    worker.send(job)
    loop = QtCore.QEventLoop()
    outcome = {}

    def poll():
        try:
            progress.check_cancel()
            while True:
                frame = worker.frames.get_nowait()
                if frame[0] == "progress":
                    progress.report(*frame[1:])
                else:
                    outcome[frame[0]] = frame[1]
                    loop.quit()
                    return
        except queue.Empty:
            return
        except Cancelled:
            outcome["cancelled"] = True
            loop.quit()

    timer = QtCore.QTimer()
    timer.setInterval(POLL_MS)
    timer.timeout.connect(poll)
    timer.start()
    try:
        loop.exec_()
    finally:
        timer.stop()
    if "cancelled" in outcome:
        end_stage_process()
        raise Cancelled("cancelled by the user")
    if "ended" in outcome:
        end_stage_process()
        raise StageFailed(f"the stage process ended unexpectedly ({outcome['ended']}); "
                          "the Report view may say why")
    if "error" in outcome:
        error = outcome["error"]
        raise error.rebuild() if isinstance(error, RebuiltError) else error
    return outcome["result"]


def _raise_in_thread(thread, outcome):
    """Raise ``Cancelled`` in ``thread`` at its next Python instruction (unless it is done)."""
    if thread.is_alive() and not outcome:
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread.ident),
                                                   ctypes.py_object(Cancelled))


def _wait_for_left_running(progress):
    """Let cancelled workers that are still running end first (the GUI stays live)."""
    from PySide import QtCore

    while _LEFT_RUNNING:
        thread = _LEFT_RUNNING[0]
        if not thread.is_alive():
            _LEFT_RUNNING.pop(0)
            continue
        progress.report("waiting for the cancelled stage to stop", 0.0)
        QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.AllEvents, POLL_MS)
        thread.join(POLL_MS / 1000.0)


class GuiProgress(Progress):
    """The progress of one command in the GUI thread: a status-bar bar with *Cancel*, the
    stage in the status bar, a busy cursor and the input guard (see the module notes).

    Use as a context manager (or ``start()`` / ``stop()``); ``cancel()`` (Esc, the button)
    makes the next ``report`` or ``check_cancel`` raise ``Cancelled``.

    Parameters
    ----------
    title : str, the command's name, shown before the stage.
    """

    def __init__(self, title):
        self.title = title
        self.cancelled = False
        self.fraction = 0.0
        self.stage_text = ""
        self._widgets = None
        self._guard = None

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, exc_type, exc, traceback):
        self.stop()
        return False

    def start(self):
        """Show the bar and guard the input (idempotent)."""
        from PySide import QtCore, QtGui

        if self._widgets is not None:
            return
        bar = QtGui.QProgressBar()
        bar.setRange(0, STEPS)
        bar.setMaximumWidth(200)
        bar.setFormat(f"{self.title}: %p%")
        button = QtGui.QToolButton()
        button.setText("Cancel")
        button.setToolTip(f"Stop '{self.title}' (Esc); the document stays as it was before "
                          "the running stage")
        button.clicked.connect(self.cancel)
        status_bar = FreeCADGui.getMainWindow().statusBar()
        status_bar.addPermanentWidget(bar)
        status_bar.addPermanentWidget(button)
        self._widgets = (bar, button)
        self._guard = _InputGuard(self, (button,))
        QtGui.QApplication.instance().installEventFilter(self._guard)
        QtGui.QApplication.setOverrideCursor(QtCore.Qt.BusyCursor)
        self._show_stage(self.title)

    def stop(self):
        """Remove the bar and the guard (idempotent)."""
        from PySide import QtGui

        if self._widgets is None:
            return
        QtGui.QApplication.instance().removeEventFilter(self._guard)
        QtGui.QApplication.restoreOverrideCursor()
        status_bar = FreeCADGui.getMainWindow().statusBar()
        for widget in self._widgets:
            status_bar.removeWidget(widget)
            widget.deleteLater()
        status_bar.clearMessage()
        self._widgets = self._guard = None

    def cancel(self):
        """Ask the running stage to stop."""
        if not self.cancelled:
            self.cancelled = True
            self._show_stage(f"{self.title}: cancelling")

    def check_cancel(self):
        if self.cancelled:
            raise Cancelled(f"{self.title}: cancelled by the user")

    def report(self, stage, fraction, message=""):
        """Move the bar to ``fraction`` of the whole command (never back) and show the stage.

        Raises
        ------
        Cancelled
            The user cancelled.
        """
        self.check_cancel()
        self.fraction = max(self.fraction, min(max(float(fraction), 0.0), 1.0))
        text = f"{self.title}: {stage}" + (f" ({message})" if message else "")
        if text != self.stage_text:
            self._show_stage(text)
        if self._widgets is not None:
            self._widgets[0].setValue(int(round(self.fraction * STEPS)))

    def _show_stage(self, text):
        self.stage_text = text
        FreeCAD.Console.PrintLog(f"Polycube: {text}\n")
        FreeCADGui.getMainWindow().statusBar().showMessage(text)


def _input_guard_class():
    from PySide import QtCore

    class InputGuard(QtCore.QObject):
        """Application event filter while a stage runs: Esc cancels; clicks, keys and
        shortcuts reach only the 3D view (to look around) and the *Cancel* button."""

        BLOCKED = {QtCore.QEvent.MouseButtonPress, QtCore.QEvent.MouseButtonRelease,
                   QtCore.QEvent.MouseButtonDblClick, QtCore.QEvent.Wheel,
                   QtCore.QEvent.KeyPress, QtCore.QEvent.KeyRelease,
                   QtCore.QEvent.ShortcutOverride, QtCore.QEvent.Shortcut,
                   QtCore.QEvent.ContextMenu, QtCore.QEvent.Close}
        KEYS = {QtCore.QEvent.KeyPress, QtCore.QEvent.KeyRelease,
                QtCore.QEvent.ShortcutOverride, QtCore.QEvent.Shortcut}

        def __init__(self, progress, allowed):
            super().__init__()
            self.progress = progress
            self.allowed = allowed

        def eventFilter(self, watched, event):
            kind = event.type()
            if kind not in self.BLOCKED or not watched.isWidgetType():
                return False
            if kind == QtCore.QEvent.KeyPress and event.key() == QtCore.Qt.Key_Escape:
                self.progress.cancel()
                return True
            if kind == QtCore.QEvent.ShortcutOverride:
                event.accept()  # no shortcut fires; the key press after it is blocked
                return True
            if kind == QtCore.QEvent.Close:  # the main window stays open
                return watched is FreeCADGui.getMainWindow()
            if kind in self.KEYS:
                return True
            return not self._is_allowed(watched)

        def _is_allowed(self, widget):
            while widget is not None:
                if widget in self.allowed or widget.inherits("Gui::View3DInventorViewer"):
                    return True
                widget = widget.parentWidget()
            return False

    return InputGuard


_GUARD_CLASS = None


def _InputGuard(progress, allowed):
    global _GUARD_CLASS
    if _GUARD_CLASS is None:
        _GUARD_CLASS = _input_guard_class()
    return _GUARD_CLASS(progress, allowed)

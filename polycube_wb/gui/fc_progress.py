# SPDX-License-Identifier: LGPL-2.1-or-later
"""Core progress protocol -> FreeCAD's progress indicator (status-bar bar in the GUI).

``Base.ProgressIndicator`` has exactly ``start(text, steps)``, ``next(can_abort)`` and
``stop()`` in FreeCAD 0.20.2. In the GUI, ``next(True)`` lets the user press Esc (and
repaints the window); the indicator then raises ``RuntimeError("abort progress
indicator")`` and stops itself, which this adapter turns into ``core.errors.Cancelled``.
Headless it prints percentages to the console.

One bar spans the whole run: the fractions reported are of the whole run (the pipeline
and the stage objects hand each stage its share through ``core.progress.SubProgress``),
so the bar only moves forward. The stage name goes to the status bar (GUI) and the log.

Start the bar (``start()``, or entering the ``with`` block) *before* ``doc.recompute()``:
recompute opens its own progress sequence, and FreeCAD ignores a sequence started
inside another one, so a bar first started from an object's ``execute`` never moves,
never repaints the window and never sees Esc (measured in the GUI, FreeCAD 0.20.2).
"""
import FreeCAD

from core.errors import Cancelled
from core.progress import Progress

STEPS = 1000
"""Resolution of the bar; each step lets FreeCAD repaint and look for Esc."""


class FreeCADProgress(Progress):
    """``core.progress.Progress`` shown by one ``Base.ProgressIndicator``.

    Use as a context manager so the bar is stopped however the work ends::

        with FreeCADProgress("Import SubD cage") as progress:
            api.subd_to_solid(path, progress=progress)

    Parameters
    ----------
    title : str
        Text of the bar; the current stage is shown after it in the status bar.
    indicator_factory : callable, optional
        Returns a new indicator object with ``start``/``next``/``stop``; defaults to
        ``FreeCAD.Base.ProgressIndicator`` (tests pass a fake one to simulate Esc).
    """

    def __init__(self, title, indicator_factory=None):
        self.title = title
        self._factory = indicator_factory or FreeCAD.Base.ProgressIndicator
        self._indicator = None
        self._stage = None
        self._done = 0
        self.cancelled = False

    def __enter__(self):
        self.start()
        return self

    def start(self):
        """Show the bar at 0 (idempotent); see the module notes on when to call it."""
        if self._indicator is None and not self.cancelled:
            self._indicator = self._factory()
            self._indicator.start(self.title, STEPS)
            self._done = 0

    def __exit__(self, exc_type, exc, traceback):
        self.stop()
        return False

    def report(self, stage, fraction, message=""):
        """Move the bar to ``fraction`` of the whole run (clamped; never backwards).

        Raises
        ------
        Cancelled
            The user pressed Esc while the bar was advancing (or earlier).
        """
        self.check_cancel()
        self.start()
        if stage != self._stage:
            self._stage = stage
            _show_stage(f"{self.title}: {stage}" + (f" ({message})" if message else ""))
        target = int(round(min(max(float(fraction), 0.0), 1.0) * STEPS))
        while self._done < target:
            self._advance()

    def check_cancel(self):
        """Raise ``Cancelled`` if the user cancelled through the progress bar."""
        if self.cancelled:
            raise Cancelled(f"{self.title}: cancelled by the user")

    def stop(self):
        """Stop the bar (idempotent)."""
        if self._indicator is not None:
            indicator, self._indicator = self._indicator, None
            indicator.stop()
        self._stage = None

    def _advance(self):
        try:
            self._indicator.next(True)
        except RuntimeError as exc:
            if "abort" not in str(exc).lower():
                raise
            # FreeCAD has already stopped its sequencer when it raises the abort.
            self._indicator = None
            self._stage = None
            self.cancelled = True
            raise Cancelled(f"{self.title}: cancelled by the user") from exc
        self._done += 1


def _show_stage(text):
    FreeCAD.Console.PrintLog(f"Polycube: {text}\n")
    if FreeCAD.GuiUp:
        import FreeCADGui

        FreeCADGui.getMainWindow().statusBar().showMessage(text)

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Core progress protocol -> FreeCAD's progress indicator (status-bar bar in the GUI).

``Base.ProgressIndicator`` has exactly ``start(text, steps)``, ``next(can_abort)`` and
``stop()`` in FreeCAD 0.20.2. In the GUI, ``next(True)`` lets the user press Esc; the
indicator then raises ``RuntimeError("abort progress indicator")`` and stops itself,
which this adapter turns into ``core.errors.Cancelled``. Headless it prints
percentages to the console.

FreeCAD only looks for a cancel request when the bar moves by a whole percent, so
cancelling takes effect at the next ``report`` that advances the bar (or at the next
``check_cancel`` after it).
"""
import FreeCAD

from core.errors import Cancelled
from core.progress import Progress

STEPS = 100
"""Resolution of the bar: one step per percent of a stage."""


class FreeCADProgress(Progress):
    """``core.progress.Progress`` shown by a ``Base.ProgressIndicator``.

    One bar runs per stage: when ``report`` names a new stage, the bar is restarted with
    the text ``"<title>: <stage>"``, so stages that count their own fraction from 0 to 1
    never make the bar run backwards.

    Use as a context manager so the bar is stopped however the work ends::

        with FreeCADProgress("Import SubD cage") as progress:
            api.subd_to_solid(path, progress=progress)

    Parameters
    ----------
    title : str
        Shown in front of the stage name.
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
        return self

    def __exit__(self, exc_type, exc, traceback):
        self.stop()
        return False

    def report(self, stage, fraction, message=""):
        """Move the bar of ``stage`` to ``fraction`` (clamped to [0, 1]).

        Raises
        ------
        Cancelled
            The user pressed Esc while the bar was advancing (or earlier).
        """
        self.check_cancel()
        if stage != self._stage:
            self.stop()
            self._stage = stage
            text = f"{self.title}: {stage}" + (f" ({message})" if message else "")
            FreeCAD.Console.PrintLog(f"Polycube: {text}\n")
            self._indicator = self._factory()
            self._indicator.start(text, STEPS)
            self._done = 0
        fraction = min(max(float(fraction), 0.0), 1.0)
        target = int(round(fraction * STEPS))
        while self._done < target:
            self._advance()

    def check_cancel(self):
        """Raise ``Cancelled`` if the user cancelled through the progress bar."""
        if self.cancelled:
            raise Cancelled(f"{self.title}: cancelled by the user")

    def stop(self):
        """Stop the current bar (idempotent)."""
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

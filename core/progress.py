# SPDX-License-Identifier: LGPL-2.1-or-later
"""Progress reporting and cancellation for long stages.

Stages accept an optional ``progress`` object with two methods; the default does
nothing, so stages are usable from plain scripts and tests.
"""


class Progress:
    """No-op progress sink; subclass it to show progress or allow cancelling."""

    def report(self, stage, fraction, message=""):
        """Called with the stage name and a fraction in [0, 1]."""

    def check_cancel(self):
        """Raise ``core.errors.Cancelled`` if the user asked to stop; default never does."""


NO_PROGRESS = Progress()


class SubProgress(Progress):
    """The part ``[start, end]`` of a parent's progress, for one step of a longer run.

    A step reports its own fraction in [0, 1]; the parent sees
    ``start + fraction * (end - start)``, so a bar spanning the whole run never jumps
    back when the next step starts counting from 0.

    Parameters
    ----------
    parent : Progress
    start, end : float, 0 <= start <= end <= 1, the parent's fractions this step covers.
    """

    def __init__(self, parent, start, end):
        self.parent = parent
        self.start = float(start)
        self.end = float(end)

    def report(self, stage, fraction, message=""):
        fraction = min(max(float(fraction), 0.0), 1.0)
        self.parent.report(stage, self.start + fraction * (self.end - self.start), message)

    def check_cancel(self):
        self.parent.check_cancel()

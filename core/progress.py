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

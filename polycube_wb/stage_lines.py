# SPDX-License-Identifier: LGPL-2.1-or-later
"""The stage a run is in, announced as ``STAGE <name>`` lines on stderr.

The batch's worker processes announce every stage so the batch can name the stage of a
process it stops; ``reconstruct --progress`` prints the same lines for a user or another
program; the command line names the stage a Ctrl-C stopped from the same tracker.
"""
import sys

from core.progress import Progress

STAGE_PREFIX = "STAGE "
ANNOUNCED = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches", "solid",
             "writing")
"""Stage names that are announced: the pipeline's core stages, then the solid and the writing
of the outputs (reported by :func:`polycube_wb.api.reconstruct_to_step` and ``subd_to_solid``)."""


class StageLines(Progress):
    """Progress that remembers the stage a run is in and writes ``STAGE <name>`` when it starts.

    Parameters
    ----------
    stream : text stream for the lines (default: ``sys.stderr`` at the time of writing).
    echo : bool, False to only remember the stage (``stage``) without writing lines.
    stage : str, the stage before the first one is announced (None: none yet).
    """

    def __init__(self, stream=None, echo=True, stage=None):
        self.stream = stream
        self.echo = echo
        self.stage = stage

    def report(self, stage, fraction, message=""):
        if stage != self.stage and stage in ANNOUNCED:
            self.announce(stage)

    def announce(self, stage):
        """Make ``stage`` the current stage and write its line (if ``echo``)."""
        self.stage = stage
        if self.echo:
            stream = self.stream or sys.stderr
            stream.write(f"{STAGE_PREFIX}{stage}\n")
            stream.flush()

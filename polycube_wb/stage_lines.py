# SPDX-License-Identifier: LGPL-2.1-or-later
"""The stage a run is in, announced as ``STAGE <name>`` lines on stderr, and Ctrl-C.

The batch's worker processes announce every stage so the batch can name the stage of a
process it stops; ``reconstruct --progress`` prints the same lines for a user or another
program; the command line names the stage a Ctrl-C stopped from the same tracker.
"""
import contextlib
import signal
import sys
import threading

from core.progress import Progress

STAGE_PREFIX = "STAGE "
ANNOUNCED = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches", "solid",
             "writing")
"""Stage names that are announced: the pipeline's core stages, then the solid and the writing
of the outputs (reported by :func:`polycube_wb.api.reconstruct_to_step` and ``subd_to_solid``)."""


class StageLines(Progress):
    """Progress that remembers the stage a run is in and writes ``STAGE <name>`` when it starts.

    Inside :meth:`ctrl_c_remembered` a Ctrl-C raises ``KeyboardInterrupt`` where the run is,
    except during an import, and stays pressed: the next progress report raises it (again).
    Imports are not interrupted because libraries do not survive it: trimesh wraps its
    optional imports in ``except BaseException`` (the Ctrl-C would be lost) and a nanobind
    module (libigl) interrupted while it loads aborts the process.

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
        self.ctrl_c = False

    def report(self, stage, fraction, message=""):
        self.check_cancel()
        if stage != self.stage and stage in ANNOUNCED:
            self.announce(stage)

    def check_cancel(self):
        """Raise ``KeyboardInterrupt`` again if Ctrl-C was pressed during the run."""
        if self.ctrl_c:
            raise KeyboardInterrupt

    def announce(self, stage):
        """Make ``stage`` the current stage and write its line (if ``echo``)."""
        self.stage = stage
        if self.echo:
            stream = self.stream or sys.stderr
            stream.write(f"{STAGE_PREFIX}{stage}\n")
            stream.flush()

    @contextlib.contextmanager
    def ctrl_c_remembered(self):
        """During the block a Ctrl-C (SIGINT) raises ``KeyboardInterrupt`` and is remembered
        (:meth:`check_cancel`). Only where Python's own handler is installed in the main
        thread: an ignored SIGINT (a background job) stays ignored."""
        if threading.current_thread() is not threading.main_thread() or \
                signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            yield
            return
        previous = signal.signal(signal.SIGINT, self._pressed)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    def _pressed(self, signum, frame):
        self.ctrl_c = True
        if not _importing(frame):
            raise KeyboardInterrupt


def _importing(frame):
    """True if ``frame`` or one of its callers runs Python's import machinery."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib._bootstrap"):
            return True
        frame = frame.f_back
    return False

# SPDX-License-Identifier: LGPL-2.1-or-later
"""The GUI's stage process: ``python -m polycube_wb.stage_worker``, one job at a time.

FreeCAD's GUI runs the stage objects' computations (:class:`polycube_wb.stage_jobs.StageJob`)
here, so that no computation, however long it holds Python's GIL (a LAPACK factorisation,
a linear-programming solve), can stop FreeCAD's event loop. The process reads jobs from
stdin and writes messages to its original stdout, each a pickled frame (:func:`write_frame`):

* in: ``(function, args)``;
* out: ``("progress", stage, fraction, message)`` while the job runs, then
  ``("result", value)`` or ``("error", exception)``.

Shapes a job returns (``Part``, once a job imported it) are pickled in OpenCascade's binary format
(:func:`polycube_wb.stage_jobs.register_shape_pickling`). Anything the stages print goes to
stderr. The GUI cancels a job by ending the process
(it starts a new one for the next job), so a cancel never waits for the job.
"""
import os
import pickle
import struct
import sys

import polycube_wb  # noqa: F401  (installs the guard that makes ``core`` ours)
from core.progress import Progress
from polycube_wb.stage_jobs import portable_error, register_shape_pickling

_HEADER = struct.Struct("<Q")
NICENESS = 5
"""Added to the process's niceness: when the stages keep every core busy, the scheduler
serves FreeCAD's GUI thread first, so the window keeps answering."""


def write_frame(stream, value):
    """Write ``value`` pickled, after its length (8 bytes, little-endian)."""
    data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def read_frame(stream):
    """The next value :func:`write_frame` wrote to ``stream``; raises EOFError at its end."""
    header = stream.read(_HEADER.size)
    if len(header) < _HEADER.size:
        raise EOFError("the stream ended")
    size = _HEADER.unpack(header)[0]
    data = stream.read(size)
    if len(data) < size:
        raise EOFError("the stream ended inside a frame")
    return pickle.loads(data)


class FrameProgress(Progress):
    """Progress written as ``("progress", ...)`` frames."""

    def __init__(self, stream):
        self.stream = stream

    def report(self, stage, fraction, message=""):
        write_frame(self.stream, ("progress", str(stage), float(fraction), str(message)))


def main():
    try:
        os.nice(NICENESS)
    except (AttributeError, OSError):  # not on this platform: the same priority as FreeCAD
        pass
    out = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # stray prints go to stderr
    jobs = sys.stdin.buffer
    progress = FrameProgress(out)
    while True:
        try:
            function, args = read_frame(jobs)
        except EOFError:
            return 0
        try:
            value = function(*args, progress)
        except Exception as exc:  # handed to the GUI, which reports it
            write_frame(out, ("error", portable_error(exc)))
        else:
            if "Part" in sys.modules:
                register_shape_pickling()
            write_frame(out, ("result", value))


if __name__ == "__main__":
    sys.exit(main())

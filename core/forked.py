# SPDX-License-Identifier: LGPL-2.1-or-later
"""Work computed ahead in a forked process, on another core, while this one goes on.

Some work of a stage is independent of what the stage does meanwhile and much of the time
needed after it: the paired decimation of the target while the labeling is made and the
polycube layout tried (:class:`core.quadmesh.base_mesh.DecimationCache`), the STEP text of a
solid while the solid is built and checked (``polycube_wb.step_io.step_text_ahead``), one
measure while another is taken (the exact export's normal jumps, a fit's distances). A thread
would not help where the other work holds the interpreter (the labeling, the layout's
mixed-integer programs, the BREP text, numpy's many small operations), so :class:`Ahead`
forks a child that runs the function and sends its pickled result back through a pipe. The
child runs the same code on a copy of the same memory, so the result is the one the parent
would compute, bit for bit. A child that fails sends nothing, and the
caller computes the result itself (raising what the child met); a result not needed is
never waited for: :meth:`Ahead.cancel` ends the child. Where the platform cannot fork, the
fork fails (no process or memory left for a child), or the process may use one core only
(:func:`core.threads.usable_cores`), nothing is started and every caller computes its result
itself.
"""
import os
import pickle
import signal

from core.threads import usable_cores


class Ahead:
    """``function(*args)`` running in a forked child from construction on.

    Parameters
    ----------
    function : callable whose result pickles; args : its arguments (the child sees the
        parent's memory as it was at the fork).
    """

    def __init__(self, function, *args):
        self._pid = self._read = None
        if not hasattr(os, "fork") or usable_cores() < 2:
            return
        try:
            read, write = os.pipe()
        except OSError:  # no descriptors left: the caller computes the result itself
            return
        try:
            pid = os.fork()
        except OSError:  # no process or memory for a child: likewise
            os.close(read)
            os.close(write)
            return
        if pid == 0:  # pragma: no cover (the child; its result is checked in the parent)
            os.close(read)
            try:
                data = pickle.dumps(function(*args), protocol=pickle.HIGHEST_PROTOCOL)
                with os.fdopen(write, "wb") as pipe:
                    pipe.write(data)
            finally:
                os._exit(0)  # no exit handlers, no flush of the parent's buffers
        os.close(write)
        self._pid, self._read = pid, read

    def result(self):
        """The function's result once the child is done, or None when nothing was started,
        the child failed or the result was taken or cancelled already (the caller then
        computes it itself)."""
        if self._pid is None:
            return None
        pid, read = self._pid, self._read
        self._pid = self._read = None
        with os.fdopen(read, "rb") as pipe:
            data = pipe.read()
        os.waitpid(pid, 0)
        return pickle.loads(data) if data else None

    def cancel(self):
        """End the child unless its result was taken (harmless when done already)."""
        if self._pid is None:
            return
        pid, read = self._pid, self._read
        self._pid = self._read = None
        os.close(read)
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:  # pragma: no cover (it ended between the two calls)
            pass
        os.waitpid(pid, 0)

# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch's progress: a terminal bar (meshes done, failed, running, elapsed and remaining)
and machine-readable lines for the GUI."""
import json
import sys
import time

WIDTH = 30


def _clock(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 3600:d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


class ProgressBar:
    """One line on ``stream`` (stderr), redrawn in place as meshes finish.

    The remaining time is the elapsed time per finished mesh times the meshes left
    (unknown until one mesh has finished).
    """

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self.started = time.monotonic()
        self.first_done = None

    def update(self, done, failed, running, total):
        """Redraw the bar; ``done`` counts the failed meshes and the skipped ones too."""
        if self.first_done is None:
            self.first_done = done
        elapsed = time.monotonic() - self.started
        run_done = done - self.first_done
        left = (_clock(elapsed / run_done * (total - done)) if run_done > 0 else "?")
        filled = int(WIDTH * done / total) if total else WIDTH
        self.stream.write(f"\r[{'#' * filled}{'.' * (WIDTH - filled)}] {done}/{total} done, "
                          f"{failed} failed, {running} running, {_clock(elapsed)} elapsed, "
                          f"{left} left ")
        self.stream.flush()

    def row(self, row):
        """Nothing: the bar shows counts only."""

    def close(self):
        """End the line."""
        self.stream.write("\n")
        self.stream.flush()


PROGRESS_PREFIX = "PROGRESS "
MESH_PREFIX = "MESH "


class ProgressLines:
    """The batch's progress for another program (the GUI's *Reconstruct folder*): one line
    per event on ``stream`` (stdout), a prefix and a JSON object.

    ``PROGRESS {"done", "failed", "running", "total"}`` when the counts change or once a
    second, ``MESH {"name", "status", "failed_stage", "message", "seconds", "skipped"}`` when
    a mesh finishes (or is found up to date).
    """

    def __init__(self, stream=None):
        self.stream = stream or sys.stdout

    def update(self, done, failed, running, total):
        """Write a ``PROGRESS`` line (``done`` counts the failed and skipped meshes too)."""
        self._write(PROGRESS_PREFIX, {"done": done, "failed": failed, "running": running,
                                      "total": total})

    def row(self, row):
        """Write the ``MESH`` line of a finished ``polycube_wb.batch.MeshRow``."""
        self._write(MESH_PREFIX, {"name": row.name, "status": row.status,
                                  "failed_stage": row.failed_stage, "message": row.message,
                                  "seconds": row.seconds, "skipped": row.skipped})

    def close(self):
        """Nothing to end (every line is complete)."""

    def _write(self, prefix, data):
        self.stream.write(prefix + json.dumps(data) + "\n")
        self.stream.flush()

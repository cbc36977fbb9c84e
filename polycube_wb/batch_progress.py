# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch's terminal progress bar: meshes done, failed, running, elapsed and remaining."""
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

    def close(self):
        """End the line."""
        self.stream.write("\n")
        self.stream.flush()

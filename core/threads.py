# SPDX-License-Identifier: LGPL-2.1-or-later
"""One BLAS / OpenMP thread for the reconstruction, so its results do not depend on the
machine's core count.

A multi-threaded BLAS splits a dot product or a matrix product into per-thread partial
sums whose number, and so whose rounding, follows the thread count. The fit feeds such
products into branching decisions (a point inside or outside, a crossing held back or
not), so last-bit differences grow into different results (the volume left outside by an
inside fit differs visibly between one OpenBLAS thread and two). The fit's
products are small (a few thousand rows), so one thread costs no time (see
``benchmarks/FIT_RESULTS.md``).
"""
import os
from contextlib import contextmanager

from core.optional_imports import optional_module

CORES_VARIABLE = "POLYCUBE_CORES"
"""Environment variable capping the cores one reconstruction may use (a positive integer);
a batch that runs several meshes at once gives each process its share through it."""


def usable_cores():
    """Cores this process may use for work split over threads or forked processes
    (:func:`core.compiled.by_rows`, :class:`core.forked.Ahead`): its CPU affinity, at most
    ``$POLYCUBE_CORES`` where that is a positive integer. Results do not depend on it, only
    the time they take. Returns an int >= 1."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cores = max(1, cores or 1)
    cap = os.environ.get(CORES_VARIABLE, "").strip()
    return min(cores, int(cap)) if cap.isdigit() and int(cap) > 0 else cores


@contextmanager
def single_threaded():
    """Limit every BLAS and OpenMP pool loaded in this process to one thread meanwhile.

    Usable as ``with single_threaded():`` or as the decorator ``@single_threaded()``; nested
    uses are harmless, and the previous limits are restored on exit (also on an exception).
    """
    threadpoolctl = optional_module("threadpoolctl")
    with threadpoolctl.threadpool_limits(limits=1):
        yield

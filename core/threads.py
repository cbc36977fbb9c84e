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
from contextlib import contextmanager

from core.optional_imports import optional_module


@contextmanager
def single_threaded():
    """Limit every BLAS and OpenMP pool loaded in this process to one thread meanwhile.

    Usable as ``with single_threaded():`` or as the decorator ``@single_threaded()``; nested
    uses are harmless, and the previous limits are restored on exit (also on an exception).
    """
    threadpoolctl = optional_module("threadpoolctl")
    with threadpoolctl.threadpool_limits(limits=1):
        yield

# SPDX-License-Identifier: LGPL-2.1-or-later
"""numba, and calls into the functions it compiles that keep a Ctrl-C a Ctrl-C.

A ``KeyboardInterrupt`` raised by a Python signal handler while a compiled function runs
(numba's dispatcher checks for signals as it allocates the arrays it returns) comes out as
``SystemError: CPUDispatcher(...) returned a result with an exception set``, with the
interrupt at the end of its chain of causes: 55 of 300 interrupts of a loop of tree queries
did. The batch worker and the command line take a ``SystemError`` for a failed stage (and
wrote a report for a mesh the user had stopped); :func:`keeps_interrupts` raises the
interrupt instead.
"""
import functools
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from core.optional_imports import optional_module

numba = optional_module("numba")

ROWS_PER_THREAD = 2048
"""Fewest rows a thread of :func:`rows_in_threads` gets: below it, starting a thread costs
more than the rows' work."""
MAX_THREADS = 4
"""Most threads :func:`rows_in_threads` runs at once."""


def keeps_interrupts(function):
    """Decorate a Python function that calls compiled ones: a ``SystemError`` caused by a
    ``KeyboardInterrupt`` (anywhere along its ``__cause__`` / ``__context__`` chain) is raised
    as that ``KeyboardInterrupt``."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except SystemError as error:
            interrupt = _interrupt_behind(error)
            if interrupt is None:
                raise
            raise interrupt from None

    return wrapper


def _interrupt_behind(error):
    """The ``KeyboardInterrupt`` in the chain of causes of ``error``, or None."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None



def rows_in_threads(run, count):
    """``run`` over consecutive row ranges of ``count`` rows in threads, results concatenated.

    The compiled kernels (``nogil=True``) release the interpreter lock, so a kernel that
    treats each row on its own (a query point, a candidate pair) runs on every core the
    process may use. Each row's result depends on that row alone, so the concatenation is the
    same bit for bit as one call over all rows, whatever the number of threads.

    Parameters
    ----------
    run : callable, ``run(rows)`` with ``rows`` a ``slice`` of ``range(count)``, returning a
        (k, ...) array for the k rows of the slice.
    count : int >= 0, number of rows.

    Returns
    -------
    (count, ...) array, ``run(slice(0, count))``.
    """
    threads = min(_usable_cores(), MAX_THREADS, max(1, count // ROWS_PER_THREAD))
    if threads == 1:
        return run(slice(0, count))
    bounds = np.linspace(0, count, threads + 1).astype(np.int64)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        parts = list(pool.map(run, [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]))
    return np.concatenate(parts)


def _usable_cores():
    """Cores this process may run on (its affinity where the platform tells it)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1

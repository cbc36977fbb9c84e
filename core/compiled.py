# SPDX-License-Identifier: LGPL-2.1-or-later
"""numba, calls into the functions it compiles that keep a Ctrl-C a Ctrl-C, and queries
spread over the cores.

A ``KeyboardInterrupt`` raised by a Python signal handler while a compiled function runs
(numba's dispatcher checks for signals as it allocates the arrays it returns) comes out as
``SystemError: CPUDispatcher(...) returned a result with an exception set``, with the
interrupt at the end of its chain of causes: 55 of 300 interrupts of a loop of tree queries
did. The batch worker and the command line take a ``SystemError`` for a failed stage (and
wrote a report for a mesh the user had stopped); :func:`keeps_interrupts` raises the
interrupt instead.

The tree queries of :mod:`core.box_tree` and the narrow phase of
:mod:`core.self_intersection` answer each query (a point, a ray, a pair of faces) on its own;
:func:`by_rows` cuts their rows into one block per core, so a fit's hundreds of queries use
both cores of a small machine with results equal bit for bit to one thread's.
"""
import functools
import os

import numpy as np

from core.optional_imports import optional_module

numba = optional_module("numba")


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


ROW_BLOCK = 4096
"""Fewest rows a block of :func:`by_rows` hands to another thread: below this a thread costs
more than it saves."""


@functools.lru_cache(maxsize=1)
def worker_pool():
    """``(pool, cores)``: the worker threads of :func:`by_rows`, one fewer than the ``cores``
    this process may use, made at the first split (a forked child, which has none of its
    parent's threads, makes its own)."""
    from concurrent.futures import ThreadPoolExecutor

    from core.threads import usable_cores

    cores = usable_cores()
    return ThreadPoolExecutor(max_workers=max(1, cores - 1)), cores


if hasattr(os, "register_at_fork"):  # POSIX only; elsewhere nothing forks
    os.register_at_fork(after_in_child=worker_pool.cache_clear)


def by_rows(kernel, rows, *args, least=ROW_BLOCK):
    """``kernel(*args)`` of a compiled function whose rows are independent, on the cores.

    ``rows`` indices into ``args`` name the arguments with one row per query (their first
    axes equal); each query's result depends on its own row and the other arguments only.
    The rows are cut into contiguous blocks, one per core this process may use (none smaller
    than ``least`` rows, :data:`ROW_BLOCK` unless a row is much work); the first block runs
    in the calling thread, the others in worker threads while it does (the kernel must be
    compiled with ``nogil=True``), and the results
    (an array, or a tuple of arrays, with one row per query) are joined in row order. So the
    result is the kernel's on all rows bit for bit, whatever the number of cores.
    """
    n = len(args[rows[0]])
    pool, cores = worker_pool()
    blocks = min(cores, n // least)
    if blocks < 2:
        return kernel(*args)
    cuts = np.linspace(0, n, blocks + 1).astype(np.int64)

    def block(k):
        part = list(args)
        for i in rows:
            part[i] = np.ascontiguousarray(args[i][cuts[k]:cuts[k + 1]])
        return part

    futures = [pool.submit(kernel, *block(k)) for k in range(1, blocks)]
    results = [kernel(*block(0))] + [future.result() for future in futures]
    if isinstance(results[0], tuple):
        return tuple(np.concatenate(parts) for parts in zip(*results))
    return np.concatenate(results)


def each_on_a_core(function, items):
    """``[function(item) for item in items]``, the items dealt round the cores this process
    may use (the first core's in the calling thread, the others' in worker threads
    meanwhile): for independent pieces of work that release the interpreter (scipy's sparse
    products, numpy's array operations), each computed as it would be alone."""
    items = list(items)
    pool, cores = worker_pool()
    if cores < 2 or len(items) < 2:
        return [function(item) for item in items]

    def every(first):
        return [function(item) for item in items[first::cores]]

    futures = [pool.submit(every, first) for first in range(1, min(cores, len(items)))]
    dealt = [every(0)] + [future.result() for future in futures]
    return [dealt[k % cores][k // cores] for k in range(len(items))]

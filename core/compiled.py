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


# SPDX-License-Identifier: LGPL-2.1-or-later
"""A Ctrl-C during a compiled call stays a KeyboardInterrupt (core/compiled.py).

numba's dispatcher turns a ``KeyboardInterrupt`` raised by a signal handler while it runs
into ``SystemError: ... returned a result with an exception set`` (seen in 55 of 300
interrupted tree queries); the batch worker took that for a failed stage and wrote a report
for a mesh the user had stopped. The chains below are built as CPython builds them.
"""
import pytest

from core.compiled import keeps_interrupts


def system_error_from(cause):
    """A ``SystemError`` raised from ``cause`` inside another one, as the dispatcher does."""
    try:
        try:
            raise cause
        except BaseException as inner:
            raise SystemError("CPUDispatcher(<function _cast>) returned a result with an "
                              "exception set") from inner
    except SystemError as middle:
        try:
            raise SystemError("returned a result with an exception set") from middle
        except SystemError as outer:
            return outer


def test_an_interrupt_behind_a_system_error_comes_out_as_the_interrupt():
    interrupt = KeyboardInterrupt()

    @keeps_interrupts
    def query():
        raise system_error_from(interrupt)

    with pytest.raises(KeyboardInterrupt) as raised:
        query()
    assert raised.value is interrupt


def test_other_system_errors_and_results_pass_through():
    @keeps_interrupts
    def broken():
        raise system_error_from(ValueError("not an interrupt"))

    with pytest.raises(SystemError) as raised:
        broken()
    assert isinstance(raised.value.__cause__.__cause__, ValueError)
    assert keeps_interrupts(lambda a, b=2: a + b)(1, b=3) == 4

# SPDX-License-Identifier: LGPL-2.1-or-later
"""``core.threads.single_threaded``: one BLAS thread meanwhile, and a clear error without
threadpoolctl."""
import sys

import pytest

from core.threads import single_threaded


def test_blas_pools_have_one_thread_inside_and_their_limit_back_after():
    import numpy  # noqa: F401  (loads the BLAS, whose pool is limited)
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]

    if not blas_threads():
        pytest.skip("numpy's BLAS has no thread pool (a reference BLAS): nothing to limit")
    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        with single_threaded():
            assert blas_threads() == [1] * len(before)
        assert blas_threads() == before


def test_missing_threadpoolctl_gives_an_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "threadpoolctl", None)
    with pytest.raises(ImportError, match="pip install threadpoolctl"):
        with single_threaded():
            pass

# SPDX-License-Identifier: LGPL-2.1-or-later
"""Work computed ahead in a forked child (core/forked.py): the child's result is the
function's, a failed child gives None (the caller computes it), a cancelled one is ended at
once, and the paired decimation built ahead is the one built in the process."""
import os
import time

import numpy as np
import pytest

from core.forked import Ahead
from core.threads import CORES_VARIABLE, usable_cores

needs_two_cores = pytest.mark.skipif(usable_cores() < 2, reason="a child is forked only "
                                     "where the process may use two cores")

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _arrays(n, scale):
    return {"values": np.arange(n, dtype=np.float64) * scale, "pid": os.getpid()}


def _fails():
    raise ValueError("not in the parent")


@needs_two_cores
def test_the_childs_result_is_the_functions_and_comes_once():
    ahead = Ahead(_arrays, 100000, 0.1)
    got = ahead.result()
    assert np.array_equal(got["values"], np.arange(100000, dtype=np.float64) * 0.1)
    assert got["pid"] != os.getpid()  # computed in the child
    assert ahead.result() is None  # taken
    ahead.cancel()  # harmless once taken


def test_a_failed_child_gives_none_and_a_cancelled_one_ends_at_once():
    assert Ahead(_fails).result() is None
    ahead = Ahead(time.sleep, 60)
    started = time.perf_counter()
    ahead.cancel()
    assert time.perf_counter() - started < 10
    assert ahead.result() is None


def test_nothing_is_forked_where_the_process_may_use_one_core(monkeypatch):
    """With the cores capped at one (a batch's share), no child is started and the caller
    computes the result itself; a cap that is not a positive integer is ignored."""
    monkeypatch.setenv(CORES_VARIABLE, "1")
    assert usable_cores() == 1
    assert Ahead(_arrays, 10, 1.0).result() is None
    for ignored in ("0", "-2", "many", ""):
        monkeypatch.setenv(CORES_VARIABLE, ignored)
        assert usable_cores() == len(os.sched_getaffinity(0))


def test_a_fork_that_fails_starts_nothing_and_leaks_no_descriptor(monkeypatch):
    """A fork refused by the system (no process or memory left) leaves the caller to compute
    the result itself, with both ends of the pipe closed."""
    monkeypatch.setenv(CORES_VARIABLE, "2")
    if usable_cores() < 2 or not hasattr(os, "fork"):
        pytest.skip("needs fork and two usable cores")

    def refused():
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", refused)
    open_before = len(os.listdir("/proc/self/fd"))
    ahead = Ahead(_arrays, 10, 1.0)
    assert ahead.result() is None
    assert len(os.listdir("/proc/self/fd")) == open_before


@pytest.mark.slow
def test_the_decimation_built_ahead_is_the_one_built_here():
    """The paired decimation of a small design taken from the child equals the one the
    process builds, faces and vertices bit for bit, with the caller's fallback reason."""
    import trimesh

    from core.quadmesh.base_mesh import DecimationCache
    from core.target_surface import TargetSurface

    mesh = trimesh.load(os.path.join(REPO, "examples", "to_simp_cantilever.stl"))
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    here = DecimationCache().build(V, F, TargetSurface(V, F), 60, 2500, "here")
    cache = DecimationCache()
    cache.start(V, F, 60, 2500)
    ahead = cache.build(V, F, TargetSurface(V, F), 60, 2500, "ahead")
    cache.close()
    assert np.array_equal(here[0].vertices, ahead[0].vertices)
    assert np.array_equal(here[0].face_vertices, ahead[0].face_vertices)
    assert ahead[1]["fallback_reason"] == "ahead"
    assert {k: v for k, v in here[1].items() if k not in ("fallback_reason", "seconds")} == \
        {k: v for k, v in ahead[1].items() if k not in ("fallback_reason", "seconds")}

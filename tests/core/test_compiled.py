# SPDX-License-Identifier: LGPL-2.1-or-later
"""A Ctrl-C during a compiled call stays a KeyboardInterrupt (core/compiled.py), queries
cut into blocks over the cores answer as one block does, work dealt round the cores comes
back in order, and
``core.precompile.compile_now`` compiles every cached function.

numba's dispatcher turns a ``KeyboardInterrupt`` raised by a signal handler while it runs
into ``SystemError: ... returned a result with an exception set`` (seen in 55 of 300
interrupted tree queries); the batch worker took that for a failed stage and wrote a report
for a mesh the user had stopped. The chains below are built as CPython builds them.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from core.compiled import each_on_a_core, keeps_interrupts

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


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


def test_work_dealt_round_the_cores_comes_back_in_order():
    """Sparse products dealt round the cores come back in the items' order, each equal bit
    for bit to the product made alone; one item or none stays in this thread."""
    import scipy.sparse as sp

    rng = np.random.default_rng(5)
    matrices = [sp.random(300, 300, density=0.05, format="csr", random_state=k)
                for k in range(7)]
    vector = rng.normal(size=300)
    dealt = each_on_a_core(lambda matrix: matrix.T @ (matrix @ vector), matrices)
    assert all(np.array_equal(got, m.T @ (m @ vector)) for got, m in zip(dealt, matrices))
    assert each_on_a_core(len, [[1, 2]]) == [2] and each_on_a_core(len, []) == []


@pytest.mark.slow
def test_queries_cut_into_blocks_answer_as_one_block(monkeypatch):
    """Nearest triangles, rival triangles and ray exits of more points than a block, on a
    sphere with points inside, and the overlapping boxes of its triangles: the blocks'
    answers joined are the kernel's on all rows (the traversal from the root), bit for bit;
    too few rows stay one call; a forked child makes its own threads."""
    import trimesh

    import core.box_tree as tree_module
    import core.compiled
    from core.box_tree import (closest_on_triangles, first_exits, nearest_triangles,
                               rival_triangles, triangle_tree)

    sphere = trimesh.creation.icosphere(subdivisions=4)
    tri = np.asarray(sphere.vertices)[np.asarray(sphere.faces)]
    tree = triangle_tree(tri, 1e-9)
    monkeypatch.setattr(core.compiled, "ROW_BLOCK", 64)
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.55, 0.55, size=(3 * 64 + 17, 3))  # inside the sphere
    one = tree_module._nearest(tree.tri, tree.order, tree.node_lo, tree.node_hi, points)
    assert np.array_equal(nearest_triangles(tree, points), one)
    assert np.array_equal(nearest_triangles(tree, points[:100]), one[:100])
    closest = closest_on_triangles(tri[one], points)[0]
    distance = np.linalg.norm(points - closest, axis=1)
    rivals = rival_triangles(tree, points, closest, distance, 1e-3, 0.5)
    assert np.array_equal(rivals, tree_module._rivals(tree.tri, tree.order, tree.node_lo,
                                                      tree.node_hi, points, closest, distance,
                                                      1e-3, 0.5))
    directions = rng.normal(size=points.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    normals = np.array(sphere.face_normals, dtype=np.float64)  # writable, as first_exits passes
    split = first_exits(tree, normals, points, directions, 3.0, 0.0, 1e-9)
    whole = tree_module._cast(tree.tri, normals, tree.order, tree.node_lo, tree.node_hi,
                              points, directions, 3.0, 0.0, 1e-9)
    assert all(np.array_equal(a, b) for a, b in zip(split, whole))
    assert (split[1] >= 0).all()  # every ray from inside leaves the sphere
    lo, hi = tree_module.face_boxes(tri * 1.01)  # boxes of neighbouring triangles overlap
    among = rng.random(len(lo)) < 0.3
    monkeypatch.setattr(tree_module, "ROW_BLOCK", 64)
    order = tree_module.tree_order(lo, hi)  # the root's children ordered on two cores
    single = np.arange(len(lo))
    tree_module._kd_levels(lo + hi, single, 0, len(lo), 4 * 2 ** 11, tree_module.LEAF_BOXES)
    assert np.array_equal(order, single)
    node_lo, node_hi, node_marked = tree_module._marked_tree(lo[order], hi[order], among[order])
    root = tree_module._overlaps_below(lo[order], hi[order], among[order], order, node_lo,
                                       node_hi, node_marked, np.array([[1, 1]]))
    assert len(root) > len(lo) and np.array_equal(tree_module.box_pairs(lo, hi, among), root)
    child = os.fork()
    if child == 0:  # pragma: no cover (the child's exit code is the assertion)
        os._exit(0 if np.array_equal(nearest_triangles(tree, points), one) else 1)
    assert os.waitpid(child, 0)[1] == 0


def test_compile_now_compiles_every_cached_function():
    """``make setup`` runs :func:`compile_now`: in a fresh process, afterwards every compiled
    function that is called from Python (those cached on disk) has its argument types
    compiled (or loaded), so the first reconstruction finds them all in the cache."""
    script = (
        "import core.box_tree as b, core.self_intersection as s\n"
        "import core.subdivision.patch_sums as p, core.fitting.responses as r\n"
        "from core.compiled import numba\n"
        "from core.precompile import compile_now\n"
        "compile_now()\n"
        "cached = [f for m in (b, s, p, r) for f in vars(m).values()\n"
        "          if isinstance(f, numba.core.registry.CPUDispatcher)\n"
        "          and type(f._cache).__name__ != 'NullCache']\n"
        "print(len(cached), sorted(f.__name__ for f in cached if not f.signatures))\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0] == "11 []"


def test_without_numba_the_command_line_says_what_to_install_and_writes_nothing(tmp_path):
    """numba missing (blocked in ``sys.modules``): the reconstruction stops at the intake with
    the install hint, exit 1; no STEP is written, only the report naming the failed stage,
    and the input is untouched."""
    source = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
    with open(source, "rb") as handle:
        before = handle.read()
    step = tmp_path / "out.step"
    script = ("import runpy, sys\n"
              "sys.modules['numba'] = None\n"
              f"sys.argv = ['polycube_wb', 'reconstruct', {source!r}, '-o', {str(step)!r},\n"
              f"            '--report', {str(tmp_path / 'out.json')!r}]\n"
              "runpy.run_module('polycube_wb', run_name='__main__')\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 1
    assert "pip install numba" in done.stdout + done.stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["out.json"]
    with open(tmp_path / "out.json", encoding="utf-8") as handle:
        intake = json.load(handle)["stages"]["intake"]
    assert intake["status"] == "failed" and "pip install numba" in intake["message"]
    with open(source, "rb") as handle:
        assert handle.read() == before

# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch's planning (inputs, names, overrides), its progress line, its default memory cap
and the peak-memory measure, without running meshes."""
import io
import json
import os
import subprocess
import sys

import pytest

from core.errors import ParameterError
from polycube_wb.batch import collect_inputs, load_overrides, plan_jobs
from polycube_wb.batch_progress import ProgressBar


def touch(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("solid x\nendsolid x\n")
    return str(path)


def test_inputs_from_files_folders_and_patterns_sorted_without_duplicates(tmp_path):
    a = touch(tmp_path / "a" / "part.stl")
    b = touch(tmp_path / "b" / "part.obj")
    c = touch(tmp_path / "b" / "z.off")
    touch(tmp_path / "b" / "notes.txt")
    found = collect_inputs([str(tmp_path / "b"), a, str(tmp_path / "*" / "*.stl")])
    assert found == [b, c, a]
    with pytest.raises(ParameterError, match="is not a mesh file, a folder"):
        collect_inputs([str(tmp_path / "b" / "missing.stl")])
    with pytest.raises(ParameterError, match="'.*nothing' is not a mesh file"):
        collect_inputs([a, str(tmp_path / "nothing")])


def test_names_are_unique_and_overrides_match_file_names(tmp_path):
    overrides = tmp_path / "o.json"
    overrides.write_text(json.dumps({"*.stl": {"fit_iterations": 7},
                                     "part.*": {"target_faces": 99}}))
    sources = ["/x/part.stl", "/y/part.obj", "/y/other.obj"]
    jobs = plan_jobs(sources, tmp_path, {"fit_iterations": 3, "target_faces": 300},
                     load_overrides(overrides), timeout=5.0)
    assert [job.name for job in jobs] == ["part", "part-2", "other"]
    assert [job.params for job in jobs] == [{"fit_iterations": 7, "target_faces": 99},
                                            {"fit_iterations": 3, "target_faces": 99},
                                            {"fit_iterations": 3, "target_faces": 300}]
    assert jobs[1].paths()["step"] == os.path.join(str(tmp_path), "part-2.step")
    assert jobs[0].timeout == 5.0


@pytest.mark.parametrize("text, words", [("[1, 2]", "expected an object"),
                                         ("{\"*\": {\"lamda\": 1}}", "unknown parameter(s) lamda"),
                                         ("{", "cannot read the override file")])
def test_bad_override_files_say_what_is_wrong(tmp_path, text, words):
    path = tmp_path / "o.json"
    path.write_text(text)
    with pytest.raises(ParameterError, match=words.replace("(", r"\(").replace(")", r"\)")):
        load_overrides(path)


def test_progress_line_counts_and_remaining_time():
    stream = io.StringIO()
    bar = ProgressBar(stream)
    bar.update(2, 0, 2, 10)          # two meshes skipped: no estimate yet
    assert "2/10 done, 0 failed, 2 running" in stream.getvalue() and "? left" in stream.getvalue()
    bar.started -= 40.0              # 40 s later, two more done (one failed): 20 s each, 6 left
    bar.update(4, 1, 2, 10)
    line = stream.getvalue().split("\r")[-1]
    assert line.startswith("[" + "#" * 12 + "." * 18 + "]")
    assert "4/10 done, 1 failed, 2 running, 0:00:40 elapsed, 0:02:00 left" in line
    bar.close()
    assert stream.getvalue().endswith("\n")


def test_peak_memory_counts_this_process_only():
    """The peak rises with memory this process touches, and a child started from a parent
    holding 300 MiB reports its own small peak (``ru_maxrss`` would report the parent's)."""
    code = ("import numpy as np, subprocess, sys\n"
            "from core.pipeline import peak_memory_mb\n"
            "before = peak_memory_mb()\n"
            "held = np.ones(300 * 2**20 // 8)\n"
            "after = peak_memory_mb()\n"
            "child = subprocess.run([sys.executable, '-c', 'from core.pipeline import "
            "peak_memory_mb; print(peak_memory_mb())'], capture_output=True, text=True,"
            " check=True)\n"
            "print(before, after, float(child.stdout))\n")
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=repo, env=dict(os.environ, PYTHONPATH=repo), check=True)
    before, after, child = map(float, done.stdout.split())
    assert after - before > 290.0
    assert child < after - 250.0


def test_default_memory_cap_is_a_share_of_the_ram_per_job():
    from polycube_wb.batch_memory import MIN_DEFAULT_MB, default_memory_limit_mb, machine_memory_mb

    total = machine_memory_mb()
    one, two = default_memory_limit_mb(1), default_memory_limit_mb(2)
    assert MIN_DEFAULT_MB <= two <= one <= total
    assert two == max(MIN_DEFAULT_MB, int(0.8 * total / 2))
    assert default_memory_limit_mb(10**6) == MIN_DEFAULT_MB


def test_progress_lines_for_the_gui_are_one_json_object_each():
    from polycube_wb.batch import MeshRow
    from polycube_wb.batch_progress import MESH_PREFIX, PROGRESS_PREFIX, ProgressLines

    stream = io.StringIO()
    lines = ProgressLines(stream)
    lines.update(1, 0, 2, 5)
    lines.row(MeshRow(name="m", source="/x/m.stl", status="failed", failed_stage="fit",
                      message="memory limit of 9 MB exceeded at stage fit", seconds=1.5))
    first, second = stream.getvalue().splitlines()
    assert first.startswith(PROGRESS_PREFIX) and second.startswith(MESH_PREFIX)
    assert json.loads(first[len(PROGRESS_PREFIX):]) == {"done": 1, "failed": 0, "running": 2,
                                                        "total": 5}
    assert json.loads(second[len(MESH_PREFIX):]) == {
        "name": "m", "status": "failed", "failed_stage": "fit", "seconds": 1.5,
        "message": "memory limit of 9 MB exceeded at stage fit", "skipped": False}


def test_meshes_run_at_once_share_the_cores():
    """A local batch of several meshes at once gives each process its share of the cores
    (at least one), a Dask worker's mesh one core, and a job's own setting is kept."""
    from core.threads import usable_cores
    from polycube_wb.batch import MeshJob, _sharing_cores

    jobs = [MeshJob("/a.stl", "a", "/out", {}), MeshJob("/b.stl", "b", "/out", {}, cores=3)]
    shared = _sharing_cores(jobs, max(1, usable_cores() // 4))
    assert shared[0].cores == max(1, usable_cores() // 4) and shared[1].cores == 3
    assert _sharing_cores(jobs, None)[0].cores is None
    assert jobs[0].cores is None  # the caller's jobs are not changed

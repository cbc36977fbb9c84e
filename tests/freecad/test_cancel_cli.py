# SPDX-License-Identifier: LGPL-2.1-or-later
"""Ctrl-C on the command line: real processes, a real SIGINT, at every stage.

``reconstruct --progress`` announces each stage on stderr (``STAGE <name>``); the test
waits for a stage's line, sends SIGINT and holds the process to: exit 130, stderr the stage
lines and then exactly one line ``cancelled at stage S; nothing was written`` naming the last
stage announced (no traceback), nothing on stdout, and the output folder exactly as before
(the existing STEP file and report keep their bytes, no new output, no temporary file).
The level-set cantilever (344 triangles), with a long fit where the fit is interrupted.
"""
import hashlib
import json
import os
import re
import signal
import subprocess
import sys

import pytest

from polycube_wb.stage_lines import ANNOUNCED, STAGE_PREFIX

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MESH = os.path.join(REPO, "..", "shared", "data", "meshes", "to_levelset_cantilever_tiny.stl")
RUN_SECONDS = 300
"""Hang guard on one run (a whole run takes about 15 s on a loaded machine)."""
OLD_STEP, OLD_REPORT = b"ISO-10303-21; an older result\n", b'{"older": "report"}\n'
LONG_FIT = ("--fit-iterations", "3000", "--fit-convergence", "0")
"""A fit that runs every one of its 3,000 iterations (about 100 s here): a run is surely in it
when it is interrupted, however fast the stages before it have become."""
BATCH_REDRAWS = 5
"""The batch is stopped at its fifth progress line: its meshes are inside the pipeline."""
CANCELLED = re.compile(r"cancelled at stage (\w+); nothing was written")
AFTER_WRITING = "cancelled after the outputs were written; they are complete"


def folder_digest(folder):
    """``{file name: sha256}`` of the files in ``folder``."""
    found = {}
    for name in sorted(os.listdir(folder)):
        with open(os.path.join(folder, name), "rb") as handle:
            found[name] = hashlib.sha256(handle.read()).hexdigest()
    return found


def outputs_folder(tmp_path):
    """A folder holding an older STEP file and report that the run is asked to replace."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "result.step").write_bytes(OLD_STEP)
    (out / "report.json").write_bytes(OLD_REPORT)
    return out


def start_reconstruct(out, *extra):
    command = [sys.executable, "-m", "polycube_wb", "reconstruct", MESH, "--progress",
               "-o", str(out / "result.step"), "--report", str(out / "report.json"),
               "--base-mesh", str(out / "base.obj"), "--labels", str(out / "labels.ply"), *extra]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def interrupt_at(process, stage):
    """Send SIGINT once ``STAGE <stage>`` is on the process's stderr; returns
    ``(exit code, stdout, stderr lines)``."""
    lines = []
    for line in process.stderr:
        lines.append(line.rstrip("\n"))
        if lines[-1] == STAGE_PREFIX + stage:
            process.send_signal(signal.SIGINT)
            break
    stdout, rest = process.communicate(timeout=RUN_SECONDS)
    return process.returncode, stdout, lines + rest.splitlines()


@pytest.fixture(scope="module", autouse=True)
def _needs_the_mesh():
    if not os.path.exists(MESH):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")


@pytest.mark.parametrize("stage", ["intake", "parts", "labeling", "basemesh", "fit", "patches",
                                   "solid"])
def test_ctrl_c_at_a_stage_writes_nothing_and_says_where(tmp_path, stage):
    out = outputs_folder(tmp_path)
    before = folder_digest(out)
    fit = LONG_FIT if stage == "fit" else ("--fit-iterations", "3")  # long where interrupted
    code, stdout, lines = interrupt_at(start_reconstruct(out, *fit), stage)
    assert code == 130, lines
    announced = [line[len(STAGE_PREFIX):] for line in lines[:-1]]
    assert lines[:-1] == [STAGE_PREFIX + name for name in announced], \
        f"only stage lines before the last line: {lines}"
    match = CANCELLED.fullmatch(lines[-1])
    assert match, f"one clear last line, got {lines[-1]!r}"
    assert match.group(1) == announced[-1], "the line names the stage the run was in"
    assert ANNOUNCED.index(announced[-1]) >= ANNOUNCED.index(stage)
    assert stdout == ""
    assert folder_digest(out) == before, "the older outputs keep their bytes, nothing new"


def test_ctrl_c_while_writing_leaves_every_output_or_none(tmp_path):
    """A Ctrl-C as the outputs are written either stops the run before any is replaced
    (exit 130) or comes too late (exit 0): never a mix of old and new files."""
    out = outputs_folder(tmp_path)
    before = folder_digest(out)
    code, stdout, lines = interrupt_at(start_reconstruct(out, "--fit-iterations", "3"), "writing")
    after = folder_digest(out)
    if code == 130:
        assert CANCELLED.fullmatch(lines[-1]), lines
        assert after == before
    else:
        assert code == 0, lines
        assert sorted(after) == ["base.obj", "labels.ply", "report.json", "result.step"]
        assert after["result.step"] != before["result.step"]
        assert after["report.json"] != before["report.json"]
        assert "wrote report:" in stdout


def test_the_run_without_ctrl_c_replaces_the_outputs(tmp_path):
    """The same command line, not interrupted: exit 0 and every output replaced (so the
    unchanged folders above come from the Ctrl-C, not from a run that writes nothing)."""
    out = outputs_folder(tmp_path)
    before = folder_digest(out)
    process = start_reconstruct(out, "--fit-iterations", "3")
    stdout, stderr = process.communicate(timeout=RUN_SECONDS)
    assert process.returncode == 0, stderr
    assert [line[len(STAGE_PREFIX):] for line in stderr.splitlines()] == \
        ["intake", "parts", "frames", "labeling", "basemesh", "fit", "patches", "writing",
         "solid", "writing"]
    after = folder_digest(out)
    assert sorted(after) == ["base.obj", "labels.ply", "report.json", "result.step"]
    assert after["result.step"] != before["result.step"]
    assert after["report.json"] != before["report.json"]


def test_ctrl_c_on_a_batch_stops_every_mesh_and_leaves_the_folder_as_it_was(tmp_path):
    """Ctrl-C in a terminal reaches the batch and its mesh processes (one process group):
    exit 130 with one line, no report, output or summary for the meshes that were running,
    an existing summary unchanged."""
    inputs, out = tmp_path / "in", tmp_path / "batch"
    inputs.mkdir()
    out.mkdir()
    for name in ("a.stl", "b.stl"):
        (inputs / name).write_bytes(open(MESH, "rb").read())
    (out / "summary.csv").write_bytes(b"mesh,status\nolder,ok\n")
    before = folder_digest(out)
    process = subprocess.Popen([sys.executable, "-m", "polycube_wb", "batch", str(inputs), "-o",
                                str(out), "--jobs", "2", *LONG_FIT, "--progress-lines"],
                               cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, start_new_session=True)
    redraws = 0
    for line in process.stdout:  # a line a second while both meshes run: stop them mid-run
        redraws += line.startswith("PROGRESS ") and '"running": 2' in line
        if redraws == BATCH_REDRAWS:
            os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C in the terminal does
            break
    stdout, stderr = process.communicate(timeout=RUN_SECONDS)
    assert process.returncode == 130, stderr
    assert stderr.splitlines() == ["cancelled; the meshes that had finished keep their outputs, "
                                   "the others have none, and the summary was not written"]
    assert "MESH " not in stdout, "no mesh finished"
    assert folder_digest(out) == before


@pytest.mark.parametrize("stage", ["patches", "solid", "writing"])
def test_ctrl_c_in_subd_to_step_writes_nothing(tmp_path, stage):
    """``subd-to-step`` on the bundled genus-3 cage: the STEP file and the report are written
    together at the end (after the limit-surface volume is measured), so a Ctrl-C in any of
    its stages leaves the older files as they were."""
    out = outputs_folder(tmp_path)
    before = folder_digest(out)
    process = subprocess.Popen([sys.executable, "-m", "polycube_wb", "subd-to-step",
                                os.path.join(REPO, "examples", "genus3_cage.obj"), "--progress",
                                "-o", str(out / "result.step"), "--report",
                                str(out / "report.json")], cwd=REPO, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    code, stdout, lines = interrupt_at(process, stage)
    assert code == 130, lines
    assert stdout == ""
    if lines[-1] == AFTER_WRITING:
        # the Ctrl-C came once the outputs were in place (only possible while writing):
        # the line says so, and both files are the new, complete ones
        assert stage == "writing", lines
        after = folder_digest(out)
        assert set(after) == set(before) and all(after[k] != before[k] for k in after)
        assert json.loads((out / "report.json").read_text())["brep"]["faces"] > 0
        return
    match = CANCELLED.fullmatch(lines[-1])
    assert match and match.group(1) == lines[-2][len(STAGE_PREFIX):], lines
    assert folder_digest(out) == before

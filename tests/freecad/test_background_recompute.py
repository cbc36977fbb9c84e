# SPDX-License-Identifier: LGPL-2.1-or-later
"""The GUI's recompute: each stage's computation run by a job runner (a worker thread or
the stage process in the GUI), its result stored before ``doc.recompute()``.

On the tiny level-set cantilever, the whole chain (Target to Deviation) recomputed through a
runner that runs each job in a thread gives the very results of the plain recompute
(the same result ids and solid), with each stage computed once; a cancel or a failure
inside a job leaves the document as the plain recompute does (earlier stages keep their
results, the stage is marked, nothing after it runs, one undo step). The stage process
(``python -m polycube_wb.stage_worker``) runs pickled jobs and hands back results, progress
and errors of their own class.
"""
import os
import subprocess
import sys
import threading

import pytest

import FreeCAD

from core.errors import Cancelled, InvalidMeshError
from tiny_chain import KINDS, REPO, TINY, record_runs



@pytest.fixture(scope="module", autouse=True)
def _needs_the_mesh():
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")


class ThreadRunner:
    """Runs each job in a new thread and waits for it; records the jobs' functions."""

    def __init__(self, fail=None):
        self.functions = []
        self.fail = fail

    def __call__(self, job, progress):
        self.functions.append(job.function.__name__)
        if self.fail is not None and self.fail[0] == len(self.functions) - 1:
            raise self.fail[1]
        outcome = {}

        def work():
            try:
                outcome["result"] = job(progress)
            except BaseException as exc:
                outcome["error"] = exc

        thread = threading.Thread(target=work)
        thread.start()
        thread.join()
        if "error" in outcome:
            raise outcome["error"]
        return outcome["result"]


def _build(doc):
    from polycube_wb import api

    target = api.make_target(doc, TINY, check_self_intersections=False)
    chain = api.make_chain(doc, target, "Solid", Fit={"Iterations": 2})
    api.make_deviation(doc, chain["Solid"], target)


def _kinds(doc):
    from polycube_wb import api

    return {api.stage_kind(obj): obj for obj in doc.Objects}


def _fresh(name):
    doc = FreeCAD.newDocument(name)
    doc.UndoMode = 1
    return doc


def test_runner_gives_the_results_of_the_plain_recompute_each_stage_computed_once():
    from polycube_wb import api

    plain, threaded = _fresh("PolycubePlain"), _fresh("PolycubeThreaded")
    try:
        _build(plain)
        assert api.recompute(plain).ok
        _build(threaded)
        ran = record_runs(threaded.Objects)
        runner = ThreadRunner()
        turns = []  # (jobs run, stages stored) at each call between stages

        def between_stages():
            stored = [obj for obj in threaded.Objects if obj.Status == "ok"]
            turns.append((len(runner.functions), len(stored)))

        api.run_in_transaction(threaded, "Chain", lambda: None, run_job=runner,
                               between_stages=between_stages)
        assert ran == [], "doc.recompute() found every stage up to date"
        assert runner.functions == ["intake", "core_stages", "core_stages", "core_stages",
                                    "_limit_solid", "_deviation"]
        # one call after each stored result that another stage follows, before its job
        assert turns == [(count, count) for count in range(1, len(runner.functions))]
        expected, got = _kinds(plain), _kinds(threaded)
        for kind in KINDS:
            obj = got[kind]
            assert obj.Status == "ok" and obj.isValid() and obj.State == ["Up-to-date"], kind
            assert obj.ResultId == expected[kind].ResultId, kind
        solid = got["Solid"].Shape
        assert solid.isValid() and len(solid.Solids) == 1
        assert abs(solid.Volume - expected["Solid"].Shape.Volume) <= 1e-9 * solid.Volume
        assert got["Deviation"].MaxDeviation == pytest.approx(
            expected["Deviation"].MaxDeviation, rel=1e-9)
        assert threaded.UndoNames == ["Chain"]
    finally:
        FreeCAD.closeDocument(plain.Name)
        FreeCAD.closeDocument(threaded.Name)


@pytest.mark.parametrize("kind", ("Target", "Fit", "Deviation"))
def test_cancel_in_a_job_marks_its_stage_and_runs_nothing_after_it(kind):
    from polycube_wb import api

    doc = _fresh(f"PolycubeRunnerCancel{kind}")
    try:
        index = KINDS.index(kind)
        runner = ThreadRunner(fail=(index, Cancelled("test: Esc")))
        with pytest.raises(Cancelled, match=f"cancelled by the user at {kind}"):
            api.run_in_transaction(doc, "Chain", lambda: _build(doc), run_job=runner)
        assert len(runner.functions) == index + 1, "no job after the cancelled one"
        objects = _kinds(doc)
        for before in KINDS[:index]:
            assert objects[before].Status == "ok" and objects[before].ResultId, before
        assert objects[kind].Status == "cancelled by the user"
        assert "Touched" in objects[kind].State and not objects[kind].ResultId, "no half result"
        for after in KINDS[index + 1:]:
            assert "Touched" in objects[after].State and not objects[after].ResultId, after
        assert doc.UndoNames == ["Chain"]
        doc.undo()
        assert doc.Objects == []
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_a_job_that_fails_marks_its_stage_invalid_and_blocks_the_stages_after_it():
    from polycube_wb import api
    from polycube_wb.stage_jobs import StageFailed

    doc = _fresh("PolycubeRunnerFailure")
    try:
        runner = ThreadRunner(fail=(KINDS.index("BaseMesh"), StageFailed("no layout here")))
        _, outcome = api.run_in_transaction(doc, "Chain", lambda: _build(doc), run_job=runner)
        objects = _kinds(doc)
        assert list(outcome.failures) == [objects["BaseMesh"].Name]
        assert objects["BaseMesh"].Status == "no layout here"
        assert not objects["BaseMesh"].isValid()
        assert objects["Segmentation"].Status == "ok"
        for after in ("Fit", "Solid", "Deviation"):
            assert not objects[after].ResultId, after
        assert len(runner.functions) == KINDS.index("BaseMesh") + 1
    finally:
        FreeCAD.closeDocument(doc.Name)


class StageProcess:
    """``python -m polycube_wb.stage_worker`` driven through its frames."""

    def __init__(self):
        self.process = subprocess.Popen([sys.executable, "-m", "polycube_wb.stage_worker"],
                                        cwd=REPO, stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE)

    def run(self, job):
        """(progress frames, last frame) of ``job``."""
        from polycube_wb.stage_worker import read_frame, write_frame

        write_frame(self.process.stdin, (job.function, job.args))
        frames = []
        while True:
            frame = read_frame(self.process.stdout)
            if frame[0] != "progress":
                return frames, frame
            frames.append(frame)

    def close(self):
        self.process.stdin.close()
        assert self.process.wait(timeout=60) == 0


def test_stage_process_runs_jobs_and_hands_back_results_progress_and_errors(tmp_path):
    import numpy as np

    from core.progress import NO_PROGRESS
    from polycube_wb import api
    from polycube_wb.stage_jobs import RebuiltError, StageJob, core_stages, read_mesh_file

    worker = StageProcess()
    try:
        frames, (kind, read) = worker.run(StageJob(read_mesh_file, (TINY,)))
        assert kind == "result"
        assert [frame[1] for frame in frames] == ["reading and validating the mesh"]
        here, mesh = api.read_target_file(TINY), read.mesh
        assert np.array_equal(mesh.vertices, here.vertices)
        assert np.array_equal(mesh.faces, here.faces)
        from polycube_wb.convert import arrays_to_mesh, mesh_to_arrays

        made = arrays_to_mesh(mesh.vertices, mesh.faces, read.binary)
        assert made.isSolid() and not made.hasInvalidNeighbourhood()
        assert np.array_equal(mesh_to_arrays(made)[1], here.faces)

        from core.params import ReconstructionParams
        from core.types import MeshSource, PipelineState

        state = PipelineState(source=MeshSource("tiny", (mesh.vertices, mesh.faces)))
        params = ReconstructionParams()
        frames, (kind, there) = worker.run(StageJob(core_stages, (state, ("intake", "parts",
                                                                          "frames", "labeling"),
                                                                  params)))
        assert kind == "result" and frames, "progress frames while the stages run"
        fractions = [frame[2] for frame in frames]
        assert fractions == sorted(fractions) and 0.0 <= fractions[0] and fractions[-1] <= 1.0
        local = core_stages(state, ("intake", "parts", "frames", "labeling"), params,
                            NO_PROGRESS)
        assert np.array_equal(there.labeling.face_label, local.labeling.face_label)

        bad = tmp_path / "broken.stl"
        bad.write_bytes(b"solid broken\nendsolid broken\n")
        _, (kind, error) = worker.run(StageJob(read_mesh_file, (str(bad),)))
        assert kind == "error"
        if isinstance(error, RebuiltError):
            error = error.rebuild()
        assert isinstance(error, InvalidMeshError), "the GUI shows it as bad input"
        assert "broken.stl" in str(error)
    finally:
        worker.close()


class ProcessRunner:
    """Runs each job in the stage process (pickled there and back, shapes in binary form)."""

    def __init__(self, worker):
        from polycube_wb.stage_jobs import register_shape_pickling

        register_shape_pickling()
        self.worker = worker

    def __call__(self, job, progress):
        from polycube_wb.stage_jobs import RebuiltError

        _, (kind, value) = self.worker.run(job)
        if kind == "error":
            raise value.rebuild() if isinstance(value, RebuiltError) else value
        return value


@pytest.mark.slow
def test_stage_process_runs_the_chain_shapes_included():
    """The solid made in the stage process comes back as a shape, and the deviation map
    sends it there: the same results as the plain recompute."""
    from polycube_wb import api

    plain, moved = _fresh("PolycubePlainP"), _fresh("PolycubeProcess")
    worker = StageProcess()
    try:
        _build(plain)
        assert api.recompute(plain).ok
        _build(moved)
        ran = record_runs(moved.Objects)
        api.run_in_transaction(moved, "Chain", lambda: None, run_job=ProcessRunner(worker))
        assert ran == [], "doc.recompute() found every stage up to date"
        expected, got = _kinds(plain), _kinds(moved)
        for kind in KINDS:
            assert got[kind].Status == "ok" and got[kind].ResultId == expected[kind].ResultId
        solid = got["Solid"].Shape
        assert solid.isValid() and len(solid.Solids) == 1
        assert len(solid.Faces) == len(expected["Solid"].Shape.Faces)
        assert abs(solid.Volume - expected["Solid"].Shape.Volume) <= 1e-9 * solid.Volume
        assert got["Deviation"].MaxDeviation == pytest.approx(
            expected["Deviation"].MaxDeviation, rel=1e-9)
    finally:
        worker.close()
        FreeCAD.closeDocument(plain.Name)
        FreeCAD.closeDocument(moved.Name)

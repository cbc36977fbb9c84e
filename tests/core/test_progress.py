# SPDX-License-Identifier: LGPL-2.1-or-later
"""Progress through the pipeline: one forward bar, the fit reports its iterations, cancel.

Also the intake of an in-memory mesh (what the document's Target object uses) and the
fit's mode and thickness parameters (what the Fit object sets).
"""
import numpy as np
import pytest
import trimesh

from core.errors import Cancelled
from core.params import ReconstructionParams
from core.pipeline import run_stages
from core.progress import Progress, SubProgress
from core.subdivision.sample_cages import cube
from core.types import BaseMeshResult, IntakeResult, MeshSource, PipelineState, TriMesh


class Recorder(Progress):
    """Keeps every report; cancels once ``cancel_after`` reports came from ``stage``."""

    def __init__(self, stage=None, cancel_after=None):
        self.reports = []
        self.stage, self.cancel_after = stage, cancel_after

    def report(self, stage, fraction, message=""):
        self.reports.append((stage, fraction))

    def check_cancel(self):
        hits = sum(stage == self.stage for stage, _ in self.reports)
        if self.cancel_after is not None and hits >= self.cancel_after:
            raise Cancelled("test cancel")


def _box_state():
    box = trimesh.creation.box(extents=(12.0, 12.0, 12.0))
    target = TriMesh(np.asarray(box.vertices, dtype=np.float64),
                     np.asarray(box.faces, dtype=np.int64))
    return PipelineState(intake=IntakeResult(target, genus=0), basemesh=BaseMeshResult(cube(10.0)))


def test_sub_progress_maps_and_clamps_into_its_span():
    parent = Recorder()
    sub = SubProgress(parent, 0.25, 0.75)
    for fraction in (-1.0, 0.0, 0.5, 1.0, 3.0):
        sub.report("fit", fraction)
    assert [f for _, f in parent.reports] == [0.25, 0.25, 0.5, 0.75, 0.75]


def test_the_fit_reports_its_iterations_inside_its_share_of_the_run():
    progress = Recorder()
    state, report, failed = run_stages(_box_state(), ["fit", "patches"],
                                       ReconstructionParams(fit_iterations=4), progress)
    assert failed is None and report["stages"]["fit"]["status"] == "ok"
    assert state.patches is not None and state.fit.cage.n_faces == 6
    fractions = [fraction for _, fraction in progress.reports]
    assert fractions == sorted(fractions), "the run's bar never goes back"
    inside_fit = [f for stage, f in progress.reports if stage == "fit"]
    # run_stages reports the fit's start (0); the fit its least-squares start (0) and its
    # iterations, within [0, 1/2].
    assert len(inside_fit) == 2 + report["fit"]["iterations"]
    assert all(0.0 <= f <= 0.5 + 1e-12 for f in inside_fit)
    assert inside_fit[-1] == pytest.approx(0.5)


def test_cancel_inside_the_fit_stops_the_run():
    progress = Recorder(stage="fit", cancel_after=3)
    state, report, failed = run_stages(_box_state(), ["fit", "patches"],
                                       ReconstructionParams(fit_iterations=50), progress)
    assert isinstance(failed, Cancelled)
    assert report["stages"]["fit"]["status"] == "failed"
    assert report["stages"]["patches"]["status"] == "skipped"
    assert sum(stage == "fit" for stage, _ in progress.reports) == 3


def test_intake_validates_an_in_memory_mesh():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    source = MeshSource("box in memory", (np.asarray(box.vertices), np.asarray(box.faces)))
    state, report, failed = run_stages(PipelineState(source=source), ["intake"],
                                       ReconstructionParams(units="cm"))
    assert failed is None
    assert isinstance(state.intake, IntakeResult) and state.intake.genus == 0
    assert len(state.intake.target.faces) == 12
    # the target is scaled to millimetres; the report keeps the file's units
    assert np.ptp(state.intake.target.vertices, axis=0) == pytest.approx([10.0, 20.0, 30.0])
    assert report["input"]["genus"] == 0 and report["input"]["file"] == "box in memory"
    assert report["input"]["bbox_diagonal"] == pytest.approx(np.sqrt(14.0))


def test_a_stage_without_its_inputs_is_refused_before_anything_runs():
    progress = Recorder()
    with pytest.raises(ValueError, match="'fit' stage needs the basemesh result"):
        run_stages(PipelineState(intake=_box_state().intake), ["fit"], ReconstructionParams(),
                   progress)
    assert progress.reports == []
    with pytest.raises(ValueError, match="'frames' stage needs the parts result"):
        run_stages(PipelineState(intake=_box_state().intake), ["frames"], ReconstructionParams())
    # an earlier stage of the same run provides it
    state, report, failed = run_stages(PipelineState(intake=_box_state().intake),
                                       ["parts", "frames"], ReconstructionParams())
    assert failed is None and state.frames.report["parts"] == 1 == report["frames"]["parts"]


def test_cancel_inside_the_labeling_stops_before_the_repair():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    source = MeshSource("box", (np.asarray(box.vertices), np.asarray(box.faces)))
    progress = Recorder(stage="labeling", cancel_after=2)
    state, report, failed = run_stages(PipelineState(source=source),
                                       ["intake", "parts", "frames", "labeling", "basemesh"],
                                       ReconstructionParams(), progress)
    assert isinstance(failed, Cancelled)
    assert report["stages"]["labeling"]["status"] == "failed"
    assert report["stages"]["basemesh"]["status"] == "skipped"
    assert state.frames is not None and state.labeling is None
    # the runner's start of the stage, then the labeling's own report after HBECVT
    assert [f for stage, f in progress.reports if stage == "labeling"] == [
        pytest.approx(3 / 5), pytest.approx(3 / 5 + 0.5 / 5)]


def test_fit_mode_and_thickness_reach_the_fit():
    from core.errors import ParameterError

    with pytest.raises(ParameterError, match="fit_mode must be one of inside, best-fit, none"):
        ReconstructionParams(fit_mode="outside")
    with pytest.raises(ParameterError, match="fit_t_min must be between"):
        ReconstructionParams(fit_t_min=-1.0)
    params = ReconstructionParams(fit_iterations=2, fit_mode="inside", fit_t_min=0.0)
    _, report, failed = run_stages(_box_state(), ["fit"], params)
    assert failed is None
    assert report["fit"]["mode"] == "inside" and report["fit"]["t_min"] == 0.0
    _, report, failed = run_stages(_box_state(), ["fit"],
                                   ReconstructionParams(fit_iterations=2, fit_mode="best-fit"))
    assert failed is None and report["fit"]["mode"] == "best-fit"


class _Work:
    """Work started ahead: logs its start and its end."""

    def __init__(self, log, intake):
        self.log = log
        log.append(("started", intake is not None))

    def close(self):
        self.log.append("closed")


def _with_work_ahead(monkeypatch, log, run=None):
    """The base-mesh stage with logged work ahead (and ``run`` in place of its own)."""
    import dataclasses

    import core.pipeline as pipeline

    stage = pipeline.STAGE_BY_NAME["basemesh"]
    changed = dataclasses.replace(stage, run=run or stage.run,
                                  ahead=(("intake",), lambda intake, params: _Work(log, intake)))
    monkeypatch.setitem(pipeline.STAGE_BY_NAME, "basemesh", changed)


def test_work_ahead_starts_after_the_intake_and_ends_when_the_run_stops(monkeypatch):
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    source = MeshSource("box", (np.asarray(box.vertices), np.asarray(box.faces)))
    log = []
    _with_work_ahead(monkeypatch, log)
    progress = Recorder(stage="labeling", cancel_after=2)
    _, report, failed = run_stages(PipelineState(source=source),
                                   ["intake", "parts", "frames", "labeling", "basemesh"],
                                   ReconstructionParams(), progress)
    assert isinstance(failed, Cancelled) and report["stages"]["basemesh"]["status"] == "skipped"
    assert log == [("started", True), "closed"]


def test_work_ahead_reaches_its_stage_and_ends_with_it(monkeypatch):
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    source = MeshSource("box", (np.asarray(box.vertices), np.asarray(box.faces)))
    log = []

    def run(intake, parts, frames, labeling, params, progress, ahead=None):
        log.append(("run", isinstance(ahead, _Work) and "closed" not in log))
        raise ValueError("stops the run here")

    _with_work_ahead(monkeypatch, log, run)
    _, report, failed = run_stages(PipelineState(source=source),
                                   ["intake", "parts", "frames", "labeling", "basemesh"],
                                   ReconstructionParams())
    assert isinstance(failed, ValueError) and report["stages"]["basemesh"]["status"] == "failed"
    assert log == [("started", True), ("run", True), "closed"]
